"""`fleet up`: the whole fleet as separate processes, with a live view and a report; and
`fleet bench sim`."""

from __future__ import annotations

import json
import math
import os
import queue
import signal
import sys
import threading
import time
from collections.abc import Callable
from concurrent import futures
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, TypeVar

import numpy as np
import typer

from fleet.cli.common import WRONG_MAP_EXIT, _check_deconfliction, _fail, _load
from fleet.cli.options import (
    ConfigOpt,
    DeconflictionOpt,
    HeadlessOpt,
    JsonOpt,
    RobotsOpt,
    SeedOpt,
    SpeedOpt,
    WorldOpt,
)

TIMED_OUT_EXIT = 3
# the job finished, but with work no robot could reach (report.json's left_out)
INCOMPLETE_EXIT = 4
# the run's status (report.json) when the coordinator stopped it: the robots' scans do not
# match the stored map of --map (exit status WRONG_MAP_EXIT)
WRONG_MAP = "wrong-map"
# The simulator is asked for the report this long at a time (wall seconds), again while it
# works (it lives and uses CPU: a starved machine slows it down), for at most REPORT_GIVE_UP_S;
# a query nothing serves yet (a simulator still starting) returns at once, and is asked again
# after REPORT_POLL_S.
REPORT_WAIT_S = 30.0
REPORT_POLL_S = 1.0
REPORT_GIVE_UP_S = 300.0
# the router's port is waited for this long at a time, again while it works, at most ..._GIVE_UP_S
ROUTER_WAIT_S = 15.0
ROUTER_GIVE_UP_S = 120.0
# an operator's respawn waits this long for the main loop, which looks every REDRAW_S
RESPAWN_WAIT_S = 5.0
MAX_ROBOTS = 64
# the fleet is looked at (and the live view redrawn) this often, in wall seconds
REDRAW_S = 0.2
# The fleet cannot go on without these; every other process can be started again by
# `fleet respawn NAME`.
FATAL_PROCESSES = ("router", "sim")

if TYPE_CHECKING:
    from fleet.bus import Bus
    from fleet.params import FleetConfig
    from fleet.protocol import Message, OpsReply, OpsRequest
    from fleet.rundir import ProcessRecord
    from fleet.supervisor.launcher import Launcher, WorkWatch
    from fleet.world import World

M = TypeVar("M", bound="Message")


def up(
    robots: RobotsOpt = 3,
    world: WorldOpt = "home",
    speed: SpeedOpt = 4.0,
    headless: HeadlessOpt = False,
    until_done: Annotated[
        bool, typer.Option("--until-done", help="Stop once every robot has finished its plan.")
    ] = False,
    timeout: Annotated[
        float | None,
        typer.Option(
            "--timeout",
            help="Stop after this many wall-clock seconds; with --until-done the exit status is "
            "then 3 (the floor was not finished).",
        ),
    ] = None,
    run_dir: Annotated[
        Path | None,
        typer.Option("--run-dir", help="Where logs and the report go (default: runs/<date-time>)."),
    ] = None,
    seed: SeedOpt = 0,
    config: ConfigOpt = None,
    deconfliction: DeconflictionOpt = None,
    loop: Annotated[
        bool,
        typer.Option(
            "--loop",
            help="Start the job again each time it finishes (the floor planned afresh), until "
            "Ctrl-C or --timeout: a long run. Not with --until-done.",
        ),
    ] = False,
    floor_map: Annotated[
        Path | None,
        typer.Option(
            "--map",
            help="Plan the cleaning on this stored ROS map (map.yaml, as `fleet explore` writes "
            "it, in the world's frame) instead of the world file; the simulator still runs the "
            "world, whose dock and start poses the robots start from. Furniture the robots find "
            "moved in since the map was made is put on it and planned round (`map changed`).",
        ),
    ] = None,
    explore_first: Annotated[
        bool,
        typer.Option(
            "--explore",
            help="First explore the world as `fleet explore` does (into RUN_DIR/explore), then "
            "clean on the map it wrote; report.json's `explored` says what exploring took. "
            "--timeout bounds both together.",
        ),
    ] = False,
) -> None:
    """Run the whole fleet: a Zenoh router, the simulator, the coordinator and N agents, each
    its own process, with a live view; writes report.json, the report pictures (report.png,
    coverage.png and SVGs of both) and the data they are drawn from at the end.

    A job that finishes with work no robot could reach (behind the body of a robot that died
    in the way, or tried by every robot in vain) ends `incomplete`: the end message and
    report.json's `left_out` name each piece and its area, report.png marks them, and the
    exit status is 4. With `--until-done`, a run stopped by `--timeout` exits with 3.
    With `--map`, a run whose robots' own maps do not match the stored map (another
    building's, or one not in the world's frame) is stopped by the coordinator, with a message
    naming the map file and report.json's status `wrong-map`; the exit status is 5.

    With `--map MAP.yaml` the coordinator plans on a stored map (the one `fleet explore`
    wrote) instead of the world file, and puts on it the furniture the robots' own maps show
    moved in since (a `map changed` event each; the lanes through it are planned round it);
    with `--explore` the fleet first explores the world, then cleans on the map it made,
    starting again from the dock (the simulator is started afresh for the cleaning, so the
    floor driven while exploring does not count as cleaned).

    Examples: `fleet up --robots 3` (the home, until Ctrl-C);
    `fleet up --robots 2 --world small --headless --until-done --timeout 300`;
    `fleet up --robots 3 --map runs/home-map/map.yaml --headless --until-done`.
    """
    from fleet.bus import Bus
    from fleet.config import ConfigError, resolve_world
    from fleet.dashboard.model import FINISHED_PHASES, BusFeed, FleetWatcher
    from fleet.plausible import Bounds
    from fleet.protocol import DEFAULT_FLEET, CoverageImage, CoverageSummary, OpsRequest
    from fleet.report.figures import render_report
    from fleet.report.summary import (
        ReportError,
        RunRecorder,
        build_report,
        job_report,
        load_run,
        missed_breakdown,
        side_brush_only,
        time_use_of,
        write_json,
    )
    from fleet.rundir import RunTable, cmdline, write_dropped, write_table
    from fleet.supervisor.launcher import Launcher, free_port
    from fleet.world import on_stored_map

    if not 1 <= robots <= MAX_ROBOTS:
        _fail(f"--robots must be between 1 and {MAX_ROBOTS}, got {robots}")
    if speed < 0 or not math.isfinite(speed):
        _fail(f"--speed must be a finite number >= 0, got {speed}")
    if timeout is not None and timeout <= 0:
        _fail(f"--timeout must be > 0 seconds, got {timeout}")
    if loop and until_done:
        _fail("--loop starts the job again when it is done: it cannot stop --until-done")
    if floor_map is not None and explore_first:
        _fail("--explore makes the map the cleaning is planned on: leave out --map")
    cfg, w = _load(config, world)
    _check_deconfliction(deconfliction)
    try:
        starts = w.start_poses(robots, cfg.robot.radius)
    except ValueError as e:
        _fail(str(e))
    world_path = str(resolve_world(world))
    run_dir = run_dir or Path("runs") / datetime.now().strftime("%Y%m%d-%H%M%S")
    if (run_dir / "coordinator.sqlite").exists():
        # a coordinator started on it would resume that run's job, finished or not
        _fail(
            f"--run-dir {run_dir} holds an earlier run (coordinator.sqlite); choose a new "
            "directory, or remove that one"
        )
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        _fail(f"--run-dir {run_dir}: {e.strerror}")
    explored = None
    if explore_first:
        explored, floor_map = _explore_first(
            cfg, w, world, robots, speed, seed, run_dir, config, timeout, headless
        )
        if timeout is not None:
            timeout = max(1.0, timeout - explored["wall_s"])
    if floor_map is not None:
        try:
            on_stored_map(w, floor_map)
        except ConfigError as e:
            _fail(str(e))

    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    common = ["--connect", endpoint] + (["--config", str(config)] if config else [])
    up_cmdline = cmdline(os.getpid()) or []

    def save_table(records: dict[str, ProcessRecord]) -> None:
        table = RunTable(DEFAULT_FLEET, endpoint, os.getpid(), world_path, records, up_cmdline)
        write_table(run_dir, table)

    launcher = Launcher(run_dir, on_change=save_table)
    stop = threading.Event()
    # a closed terminal stops the fleet as Ctrl-C does: report written, no process left
    _stop_on_signals(stop)
    out = typer.echo
    status = "interrupted"
    report_failed = False
    bus = recorder = None
    t0 = time.monotonic()
    try:
        coordinator = ["--deconfliction", deconfliction] if deconfliction else []
        if loop:
            coordinator.append("--loop")
        if floor_map is not None:
            coordinator += ["--map", str(floor_map.resolve())]
        sim = _start_fleet(launcher, port, common, world_path, speed, seed, starts, coordinator)
        bus = Bus("dashboard", "up", [endpoint])
        calls = MainThreadCalls()
        bus.serve(bus.keys.ops("respawn"), OpsRequest, _respawner(launcher, calls))
        recorder = RunRecorder(bus, Bounds.of(cfg).clock_step_s, run_dir)
        watcher = FleetWatcher(DEFAULT_FLEET, cfg.coordinator.heartbeat_timeout_s, recorder.watch)
        feed = BusFeed(bus, watcher, fetch=not headless)
        on = "" if floor_map is None else f", planned on {floor_map}"
        out(f"fleet: {robots} robots in {w.name}{on} at {speed}× — logs in {run_dir}/", err=True)
        status = _watch(watcher, feed, launcher, calls, stop, until_done, timeout, headless, t0)
        feed.pump()
        feed.close()
        wall_s = time.monotonic() - t0
        summary = _ask_sim(bus, bus.keys.sim_report(), CoverageSummary, sim)
        image = _ask_sim(bus, bus.keys.coverage_image(), CoverageImage, sim)
        makespan = watcher.makespan() if status in FINISHED_PHASES else None
        with watcher.lock:
            skipped = {rid: v.status.skipped for rid, v in watcher.robots.items() if v.status}
            time_use = {rid: time_use_of(v.status) for rid, v in watcher.robots.items() if v.status}
        dropped = {**watcher.dropped(), "sim": (summary.decode_errors, summary.implausible)}
        write_dropped(run_dir, dropped)
        job = job_report(run_dir / "coordinator.sqlite")
        # an agent's own count starts again with each plan: the coordinator's spans them all
        for rid, n in (job["given_up_waypoints"] or {}).items():
            skipped[rid] = max(n, skipped.get(rid) or 0)
        report = build_report(
            summary,
            makespan,
            wall_s,
            status,
            {
                "world": world_path,
                "robot_count": robots,
                "speed": speed,
                "seed": seed,
                "deconfliction": deconfliction or cfg.coordinator.deconfliction,
                "missed": missed_breakdown(image, w.grid(image.resolution)),
                "side_brush_only": side_brush_only(image),
                "dropped": {n: {"malformed": m, "implausible": i} for n, (m, i) in dropped.items()},
                "floor_map": None if floor_map is None else str(floor_map),
                "explored": explored,
                **job,
            },
            skipped,
            time_use,
        )
        write_json(run_dir / "report.json", report)
        recorder.finish(image, cfg.robot.cleaning_width)
        render_report(load_run(run_dir))
        out(
            f"{status}: coverage {100 * report['coverage']:.1f} %, repetition "
            f"{100 * report['repetition']:.1f} %, makespan {report['makespan_s']} s sim, "
            f"{report['wall_s']} s wall, collisions {report['collisions']} — "
            f"{run_dir / 'report.json'}, {run_dir / 'report.png'}",
            err=True,
        )
        for piece in report.get("left_out") or []:
            out(f"  {left_out_line(piece)}", err=True)
    except (TimeoutError, RuntimeError, ReportError) as e:
        typer.secho(
            f"error: could not collect the report: {e}; logs in {run_dir}/", fg="red", err=True
        )
        report_failed = True
    finally:
        if recorder is not None:
            recorder.close()
        if bus is not None:
            bus.close()
        launcher.stop_all()
    # the floor was not finished, whether the report could be collected or not
    if status == "timeout" and until_done:
        raise typer.Exit(TIMED_OUT_EXIT)
    if report_failed:
        raise typer.Exit(1)
    if status == "incomplete":
        raise typer.Exit(INCOMPLETE_EXIT)
    if status == WRONG_MAP:
        typer.secho(
            f"error: the robots' scans do not match the stored map {floor_map}: the fleet "
            f"stopped instead of cleaning on it (events and {run_dir}/coordinator.log say why)",
            fg="red",
            err=True,
        )
        raise typer.Exit(WRONG_MAP_EXIT)
    if status not in ("done", "stopped", "timeout"):
        raise typer.Exit(1 if status != "interrupted" else 130)


def explore(
    robots: RobotsOpt = 2,
    world: WorldOpt = "home",
    speed: SpeedOpt = 4.0,
    headless: HeadlessOpt = False,
    timeout: Annotated[
        float | None,
        typer.Option(
            "--timeout",
            help="Stop after this many wall-clock seconds (exit status 3); the map so far is "
            "written all the same.",
        ),
    ] = None,
    run_dir: Annotated[
        Path | None,
        typer.Option("--run-dir", help="Where logs and the map go (default: runs/<date-time>)."),
    ] = None,
    seed: SeedOpt = 0,
    config: ConfigOpt = None,
    unknown_start: Annotated[
        int,
        typer.Option(
            "--unknown-start",
            min=0,
            help="How many of the robots (the last ones) do not know where they start: each "
            "maps in a frame of its own and takes no work until the coordinator has placed its "
            "map on the merged one (refused, with an `unplaced` event, while no match is "
            "confident). explore.json's `placements` says when and how well.",
        ),
    ] = 0,
) -> None:
    """Explore an unknown home: the robots start with no map, the coordinator merges the maps
    they build (SLAM) and auctions the frontiers between known floor and the unknown (Burgard
    et al. 2005) until no frontier a robot can reach is left.

    The world file is the simulator's only: the coordinator knows what the robots report. In the
    run dir: the merged map as a ROS map_server pair (map.yaml + map.pgm, written after every
    update, so a run stopped early leaves the map so far) and map.png; explore.json (sim time
    to finish, path length per robot, frontiers assigned, and the merged map's free-space IoU
    against the true floor and the share of true walls with a mapped wall within 5 cm, scored
    from the world file after the run); explore.png and explore.svg (the merged map with each
    robot's track and the frontier goals it was sold, and the known area and the frontiers
    over sim time); the processes' logs.
    The terminal shows each update as an `explored` event: known area, frontiers, each robot's
    goal. Exit status: 0 explored, 3 stopped by --timeout, 4 done with frontiers no robot could
    reach, 130 stopped by Ctrl-C or `fleet down` (the map so far is written), 1 a process
    failed.

    Examples: `fleet explore --robots 2 --world small --headless`;
    `fleet explore --robots 3 --run-dir runs/home-map --timeout 900`;
    `fleet explore --robots 3 --unknown-start 1` (robot-2 is placed by matching its map).
    """
    from fleet.coordinator.exploring import MAP_YAML
    from fleet.report.exploration import EXPLORE_REPORT, MAP_PNG
    from fleet.report.explore_figure import EXPLORE_FIGURE

    if not 1 <= robots <= MAX_ROBOTS:
        _fail(f"--robots must be between 1 and {MAX_ROBOTS}, got {robots}")
    if speed < 0 or not math.isfinite(speed):
        _fail(f"--speed must be a finite number >= 0, got {speed}")
    if timeout is not None and timeout <= 0:
        _fail(f"--timeout must be > 0 seconds, got {timeout}")
    if unknown_start >= robots:
        _fail(
            f"--unknown-start {unknown_start}: at least one of the {robots} robots must know "
            "where it starts, or no map would fix the fleet's frame"
        )
    cfg, w = _load(config, world)
    if unknown_start and cfg.agent.pose_source != "slam":
        _fail("--unknown-start needs agent.pose_source slam: only a SLAM map can be placed")
    run_dir = run_dir or Path("runs") / datetime.now().strftime("%Y%m%d-%H%M%S")
    report = _exploration(
        cfg, w, world, robots, speed, seed, run_dir, config, timeout, headless, unknown_start
    )
    status = report["status"]
    lengths = ", ".join(f"{rid} {m:.1f} m" for rid, m in report["path_length_m"].items())
    typer.echo(
        f"{status} after {report['sim_s']} s sim ({report['wall_s']} s wall): "
        f"free-space IoU {report['free_iou']:.3f}, {report['frontiers']['assigned']} frontiers "
        f"assigned, driven {lengths} — {run_dir / MAP_YAML}, {run_dir / MAP_PNG}, "
        f"{run_dir / EXPLORE_REPORT}, {run_dir / EXPLORE_FIGURE}.png",
        err=True,
    )
    exits = {"done": 0, "incomplete": INCOMPLETE_EXIT, "timeout": TIMED_OUT_EXIT}
    exits |= dict.fromkeys(("stopped", "interrupted"), 130)
    raise typer.Exit(exits.get(status, 1))


def _explore_first(
    cfg: FleetConfig,
    w: World,
    world: str,
    robots: int,
    speed: float,
    seed: int,
    run_dir: Path,
    config: Path | None,
    timeout: float | None,
    headless: bool,
) -> tuple[dict[str, Any], Path]:
    """`fleet up --explore`'s first part: the world explored into ``run_dir``/explore; what it
    took (for report.json's ``explored``) and the map it wrote. Exits unless the exploring
    finished (every reachable frontier mapped, or only unreachable ones left)."""
    from fleet.coordinator.exploring import MAP_YAML

    into = run_dir / "explore"
    report = _exploration(cfg, w, world, robots, speed, seed, into, config, timeout, headless)
    if report["status"] not in ("done", "incomplete"):
        _fail(f"exploring ended {report['status']}: no cleaning on a map not finished; see {into}/")
    typer.echo(
        f"explored in {report['sim_s']} s sim (free-space IoU {report['free_iou']:.3f}); "
        f"cleaning on {into / MAP_YAML}",
        err=True,
    )
    keys = ("status", "sim_s", "wall_s", "path_length_m", "known_m2", "free_iou", "walls_within")
    return {k: report[k] for k in keys} | {"dir": "explore"}, into / MAP_YAML


def _exploration(
    cfg: FleetConfig,
    w: World,
    world: str,
    robots: int,
    speed: float,
    seed: int,
    run_dir: Path,
    config: Path | None,
    timeout: float | None,
    headless: bool,
    unknown_start: int = 0,
) -> dict[str, Any]:
    """Explore ``w`` with ``robots`` robots, the last ``unknown_start`` of them not told their
    start, into ``run_dir`` (the fleet's processes, their logs, the merged map, map.png,
    explore.json and its picture); explore.json's content."""
    from fleet.bus import Bus
    from fleet.config import resolve_world
    from fleet.coordinator.exploring import MAP_PGM, MAP_YAML
    from fleet.dashboard.model import BusFeed, FleetWatcher
    from fleet.plausible import Bounds
    from fleet.protocol import DEFAULT_FLEET, OpsRequest
    from fleet.report.exploration import EXPLORE_REPORT, MAP_PNG, placements, write_map_png
    from fleet.report.explore_figure import render_explore
    from fleet.report.summary import TRACKS_FILE, RunRecorder, read_tracks, write_json
    from fleet.rundir import RunTable, cmdline, write_table
    from fleet.supervisor.launcher import Launcher, free_port
    from fleet.world import load_ros_map

    try:
        starts = w.start_poses(robots, cfg.robot.radius)
    except ValueError as e:
        _fail(str(e))
    world_path = str(resolve_world(world))
    if (run_dir / "coordinator.sqlite").exists() or (run_dir / MAP_YAML).exists():
        _fail(f"--run-dir {run_dir} holds an earlier run; choose a new directory")
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        _fail(f"--run-dir {run_dir}: {e.strerror}")
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    common = ["--connect", endpoint] + (["--config", str(config)] if config else [])
    up_cmdline = cmdline(os.getpid()) or []

    def save_table(records: dict[str, ProcessRecord]) -> None:
        table = RunTable(DEFAULT_FLEET, endpoint, os.getpid(), world_path, records, up_cmdline)
        write_table(run_dir, table)

    launcher = Launcher(run_dir, on_change=save_table)
    stop = threading.Event()
    _stop_on_signals(stop)
    status, bus, recorder, t0 = "interrupted", None, None, time.monotonic()
    try:
        explore = ["--explore", str(run_dir)]
        _start_fleet(
            launcher, port, common, world_path, speed, seed, starts, explore, unknown_start
        )
        bus = Bus("dashboard", "up", [endpoint])
        calls = MainThreadCalls()
        bus.serve(bus.keys.ops("respawn"), OpsRequest, _respawner(launcher, calls))
        recorder = RunRecorder(bus, Bounds.of(cfg).clock_step_s, run_dir)
        watcher = FleetWatcher(DEFAULT_FLEET, cfg.coordinator.heartbeat_timeout_s, recorder.watch)
        feed = BusFeed(bus, watcher, fetch=not headless)
        typer.echo(f"fleet: {robots} robots exploring {w.name} at {speed}× — {run_dir}/", err=True)
        status = _watch(watcher, feed, launcher, calls, stop, True, timeout, headless, t0)
        feed.pump()
        feed.close()
        with watcher.lock:
            sim_s = watcher.finished_at if watcher.finished_at is not None else watcher.clock
    finally:
        if recorder is not None:
            recorder.close()
        if bus is not None:
            bus.close()
        launcher.stop_all()
    if not (run_dir / MAP_YAML).exists():
        _fail(f"no map was written (no robot reported its map); logs in {run_dir}/")
    tracks = read_tracks(run_dir / TRACKS_FILE)
    wall_s = time.monotonic() - t0
    report = _explore_report(run_dir, cfg, w, starts[0], status, sim_s, wall_s, tracks)
    unknown = {f"robot-{i}": starts[i] for i in range(robots - unknown_start, robots)}
    if unknown:
        report["placements"] = placements(run_dir / "coordinator.sqlite", unknown)
    write_json(run_dir / EXPLORE_REPORT, report)
    write_map_png(run_dir / MAP_PGM, run_dir / MAP_PNG)
    render_explore(run_dir, load_ros_map(run_dir / MAP_YAML), tracks, report)
    return report


def _explore_report(
    run_dir: Path,
    cfg: FleetConfig,
    world: World,
    start: tuple[float, float, float],
    status: str,
    sim_s: float,
    wall_s: float,
    tracks: dict[str, np.ndarray],
) -> dict[str, Any]:
    """explore.json: how the exploration ended and what it took, and the merged map scored
    against the world's true floor (the truth read here only, after the run): free-space IoU,
    ``walls_within``, the share of the true walls with a mapped wall within 5 cm,
    ``plan_floor``, the floor a cleaning plan on the map loses against one on the world file,
    by cause (``fleet.report.exploration.plan_floor_lost``), and ``growth``, the merged map as
    it grew ([sim s, known m², frontiers] per update)."""
    from fleet.coordinator.exploring import MAP_YAML
    from fleet.report.exploration import (
        free_iou,
        frontier_counts,
        growth,
        path_lengths,
        plan_floor_lost,
        true_floor,
        walls_within,
    )
    from fleet.world import load_ros_map

    mapped = load_ros_map(run_dir / MAP_YAML)
    truth, floor = true_floor(world, mapped.resolution, (start[0], start[1]))
    return {
        "status": status,
        "world": world.name,
        "sim_s": round(sim_s, 1),
        "wall_s": round(wall_s, 1),
        "path_length_m": path_lengths(tracks),
        "frontiers": frontier_counts(run_dir / "coordinator.sqlite"),
        "growth": growth(run_dir / "coordinator.sqlite"),
        "known_m2": round(float((mapped.free | mapped.occupied).sum()) * mapped.resolution**2, 2),
        "true_floor_m2": round(float(floor.sum()) * truth.resolution**2, 2),
        "free_iou": round(free_iou(mapped, truth, floor), 4),
        "walls_within": round(walls_within(mapped, truth, floor), 4),
        "plan_floor": plan_floor_lost(
            mapped,
            world,
            (start[0], start[1]),
            cfg.robot.radius + cfg.coordinator.wall_clearance,
            cfg.robot.cleaning_width / 2,
        ),
        "map": MAP_YAML,
    }


def _stop_on_signals(stop: threading.Event) -> None:
    """Set ``stop`` on SIGINT, SIGTERM or SIGHUP. On SIGHUP the terminal is gone (a closed
    window or SSH session): what would be printed has nowhere to go, and writing to it would
    fail before the report is written, so stdout and stderr go to /dev/null."""

    def on_signal(signum: int, _frame: object) -> None:
        if signum == signal.SIGHUP:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            os.dup2(devnull, sys.stderr.fileno())
        stop.set()

    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, on_signal)


def _start_fleet(
    launcher: Launcher,
    port: int,
    common: list[str],
    world_path: str,
    speed: float,
    seed: int,
    starts: list[tuple[float, float, float]],
    coordinator: list[str],
    unknown_start: int = 0,
) -> WorkWatch:
    """Start the router (and wait for its port), the simulator, the coordinator (its state in
    the run dir, with the extra arguments ``coordinator``) and one agent per start pose, the
    last ``unknown_start`` not told theirs (the coordinator waits only for the others: those
    are ready once placed); the simulator's watch."""
    from fleet.supervisor.launcher import WorkWatch, wait_for_port

    run_dir = launcher.run_dir
    router = WorkWatch(launcher.start("router", ["router", "--listen", f"tcp/127.0.0.1:{port}"]))
    waited = 0.0
    while not wait_for_port("127.0.0.1", port, ROUTER_WAIT_S):
        waited += ROUTER_WAIT_S
        if not router.working() or waited >= ROUTER_GIVE_UP_S:
            _fail(f"the Zenoh router did not start; see {run_dir / 'router.log'}")
    sim_args = ["sim", "--world", world_path, "--speed", str(speed), "--seed", str(seed)]
    sim = WorkWatch(launcher.start("sim", [*sim_args, *common]))
    state = ["--state", str(run_dir / "coordinator.sqlite"), *coordinator]
    robots = ["--robots", str(len(starts) - unknown_start)]
    launcher.start("coordinator", ["coordinator", *robots, "--world", world_path, *common, *state])
    for i, (x, y, th) in enumerate(starts):
        rid = f"robot-{i}"
        state = ["--state-dir", str(run_dir / rid)]
        if i >= len(starts) - unknown_start:
            state.append("--unknown-start")
        launcher.start(rid, ["agent", "--id", rid, "--start", f"{x},{y},{th}", *common, *state])
    return sim


def _ask_sim(bus: Bus, key: str, cls: type[M], sim: WorkWatch) -> M:
    """The simulator's answer on ``key`` for the report. A starved machine can keep a live
    simulator from answering (or from serving at all yet: a query nothing serves returns at
    once) for long, so it is asked again, every REPORT_POLL_S at most, while it works (judged
    over each REPORT_WAIT_S), for at most REPORT_GIVE_UP_S; TimeoutError once it has exited,
    has stopped or hung, or then."""
    from fleet.protocol import Request

    start = looked = time.monotonic()
    while True:
        asked = time.monotonic()
        try:
            return bus.request(key, Request("up"), cls, timeout=REPORT_WAIT_S)
        except TimeoutError:
            pass
        time.sleep(max(0.0, REPORT_POLL_S - (time.monotonic() - asked)))
        now = time.monotonic()
        why = ""
        if not sim.alive():
            why = "has exited"
        elif now - looked >= REPORT_WAIT_S:
            looked = now
            if not sim.working():
                why = "is not working (stopped or hung)"
            elif now - start >= REPORT_GIVE_UP_S:
                why = "still works but does not answer"
            else:
                print(
                    f"the simulator has not answered in {now - start:.0f} s; it works (a busy "
                    "machine): asking again",
                    file=sys.stderr,
                    flush=True,
                )
        if why:
            raise TimeoutError(f"{key}: no answer in {now - start:.0f} s; the simulator {why}")


class MainThreadCalls:
    """Calls asked for on other threads, made by the main thread between two looks at the
    fleet. A process started from a Zenoh callback thread would get its parent-death signal
    when that thread ends (Linux ties ``PR_SET_PDEATHSIG`` to the thread that forked)."""

    def __init__(self) -> None:
        self._pending: queue.Queue[tuple[Callable[[], Any], futures.Future]] = queue.Queue()

    def call(self, fn: Callable[[], Any], timeout: float) -> Any:
        """``fn()`` made by the main thread; raises TimeoutError if it does not get to it."""
        done: futures.Future = futures.Future()
        self._pending.put((fn, done))
        return done.result(timeout)

    def run_pending(self) -> None:
        while True:
            try:
                fn, done = self._pending.get_nowait()
            except queue.Empty:
                return
            try:
                done.set_result(fn())
            except Exception as e:
                done.set_exception(e)


def _respawner(launcher: Launcher, calls: MainThreadCalls) -> Callable[[OpsRequest], OpsReply]:
    """The answer to `fleet respawn NAME`: start NAME again with the arguments it had (plus
    ``--respawn`` for an agent, which then reloads its map and pose from its --state-dir; the
    coordinator resumes from its --state file)."""
    from fleet.protocol import OpsReply

    def answer(req: OpsRequest) -> OpsReply:
        try:
            return calls.call(lambda: respawn(req), RESPAWN_WAIT_S)
        except futures.TimeoutError:
            return OpsReply(False, "fleet up did not get to it: it is stopping")

    def respawn(req: OpsRequest) -> OpsReply:
        if req.verb != "respawn":
            return OpsReply(False, f"unknown verb {req.verb!r}; this key answers respawn")
        if req.name in FATAL_PROCESSES:
            return OpsReply(False, f"{req.name} cannot be respawned: the fleet stops without it")
        record = launcher.records.get(req.name)
        if record is None:
            names = ", ".join(n for n in launcher.records if n not in FATAL_PROCESSES)
            return OpsReply(False, f"no process {req.name!r} in this fleet; there are: {names}")
        args = list(record.argv)
        if args[:1] == ["agent"] and "--respawn" not in args:
            args.append("--respawn")
        try:
            proc = launcher.restart(req.name, args)
        except (ValueError, RuntimeError, OSError) as e:
            return OpsReply(False, str(e))
        print(f"respawned {req.name} for {req.sender} (pid {proc.pid})", file=sys.stderr)
        return OpsReply(True, "")

    return answer


def _watch(watcher, feed, launcher, calls, stop, until_done, timeout, headless, t0) -> str:
    """Show progress until done, timeout, a signal, a dead router or simulator, or a coordinator
    that failed with an error; returns why it stopped. Another process that dies (a killed
    coordinator, any agent) is reported once, and the run goes on. On a
    terminal (and without --headless) the live view of `fleet dashboard` shows it, until q
    closes the view; then, as without a terminal, plain lines."""
    from rich.console import Console

    from fleet.dashboard.term import TerminalView, ViewControl
    from fleet.rundir import write_dropped
    from fleet.supervisor.ops import ProcessActions

    console = Console(stderr=True)
    control = ViewControl(watcher, ProcessActions(launcher.run_dir))
    view = None
    if not headless and console.is_terminal:
        view = TerminalView(watcher, control, console)
    last_line = -1e9
    reported: dict[str, int] = {}
    dropped: dict[str, tuple[int, int | None]] = {}

    def say(text: str, kind: str) -> None:
        if view is not None:
            watcher.note(kind, text)
        else:
            console.print(f"[{'red' if kind == 'error' else 'yellow'}]{text}")

    try:
        if view is not None:
            view.start()
        while not stop.wait(REDRAW_S):
            calls.run_pending()
            feed.pump()
            wall = time.monotonic() - t0
            if view is not None and control.quit.is_set():
                view.stop()
                view = None
                watcher.take_events()  # the view has shown them
                console.print("the view is closed; the fleet runs on (Ctrl-C stops it)")
            if view is not None:
                view.draw()
            else:
                for line in watcher.take_events():
                    print(f"event: {line}", file=sys.stderr, flush=True)
                if wall - last_line >= 5.0:
                    print(watcher.line(wall), file=sys.stderr, flush=True)
                    last_line = wall
            dead = launcher.dead()
            # a coordinator that failed by itself (not killed by a signal) fails again if respawned
            fatal = {
                n: c
                for n, c in dead.items()
                if n in FATAL_PROCESSES or (n == "coordinator" and c > 0)
            }
            if fatal:
                name, code = next(iter(fatal.items()))
                log = launcher.run_dir / (name + ".log")
                if view is not None:
                    view.stop()
                    view = None
                if name == "coordinator" and code == WRONG_MAP_EXIT:
                    say(f"the coordinator refused the stored map; see {log}", "error")
                    return WRONG_MAP
                say(f"{name} exited with code {code}; see {log}", "error")
                return "error"
            for name, code in dead.items():
                restarts = launcher.records[name].restarts
                if reported.get(name) != restarts:
                    reported[name] = restarts
                    say(
                        f"{name} exited with code {code}; `fleet respawn {name}` starts it again",
                        "lost",
                    )
            watcher.set_restarts({n: r.restarts for n, r in launcher.records.items()})
            if watcher.dropped() != dropped:
                dropped = watcher.dropped()
                write_dropped(launcher.run_dir, dropped)
            if until_done and watcher.done:
                return watcher.phase
            if timeout is not None and wall > timeout:
                return "timeout"
        return watcher.phase if watcher.done else "stopped"
    finally:
        if view is not None:
            view.stop()
        control.close()
        print(watcher.line(time.monotonic() - t0), file=sys.stderr, flush=True)


def bench_sim(
    robots: Annotated[int, typer.Option("--robots", "-n", help="Scripted robots.")] = 3,
    seconds: Annotated[float, typer.Option("--seconds", "-s", help="Sim seconds to run.")] = 60.0,
    world: WorldOpt = "home",
    as_json: JsonOpt = False,
    config: ConfigOpt = None,
) -> None:
    """Run the simulator core alone with scripted robots (no bus) and print its real-time
    factor (`rtf`) and lidar rays per second (`rays_per_s`).

    Robots drive arcs whose curvature changes slowly, so they sweep the world, hit walls and
    each other. The loop is the live simulator's (`SimCore.tick`): physics, lidar, odometry,
    cleaning, true poses and the run's summary at the rates a live run computes them; only
    the bus is left out.
    On a shared machine compare `rtf_cpu` (sim seconds per CPU second of this process), which
    other work disturbs much less than `rtf`; `load_avg` is the 1-minute load when it finished.
    """
    import os

    import numpy as np

    from sim_server.core import SimCore

    if robots < 1 or seconds <= 0:
        _fail("--robots must be >= 1 and --seconds > 0")
    cfg, w = _load(config, world)
    try:
        starts = w.start_poses(robots, cfg.robot.radius, spacing=2 * cfg.robot.radius + 0.06)
    except ValueError as e:
        _fail(str(e))
    core = SimCore(w, cfg, seed=0)
    for i, pose in enumerate(starts):
        core.add_robot(f"r{i}", pose)
    rng = np.random.default_rng(1)
    phase = rng.uniform(0, 2 * np.pi, robots)
    steps = round(seconds * cfg.sim.physics_hz)
    scans = 0
    t0, cpu0 = time.perf_counter(), time.process_time()
    for k in range(steps):
        if k % 10 == 0:
            t = core.t
            for i in range(robots):
                core.set_cmd(f"r{i}", 0.4, 0.8 * math.sin(0.3 * t + phase[i]))
        scans += len(core.tick(time.perf_counter() - t0).scans)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - cpu0
    result = {
        "robots": robots,
        "world": w.name,
        "sim_seconds": round(core.t, 3),
        "wall_s": round(wall, 3),
        "rtf": round(core.t / wall, 2),
        "cpu_s": round(cpu, 3),
        "rtf_cpu": round(core.t / cpu, 2),
        "load_avg": round(os.getloadavg()[0], 2),
        "rays_per_s": round(scans * cfg.lidar.beams / wall),
        "scans": scans,
        "coverage": round(core.cleaning.coverage(), 4),
    }
    if as_json:
        print(json.dumps(result))
    else:
        typer.echo(
            f"{robots} robots, {result['sim_seconds']} sim s in {result['wall_s']} s wall: "
            f"{result['rtf']}× real time ({result['rtf_cpu']}× per CPU second), "
            f"{result['rays_per_s']:,} rays/s, load average {result['load_avg']}"
        )


def register(
    app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app: typer.Typer
) -> None:
    app.command("up")(up)
    app.command("explore")(explore)
    bench_app.command("sim")(bench_sim)


def left_out_line(piece: dict[str, Any]) -> str:
    """The end text's line for a piece of report.json's ``left_out``: its id, area, where it
    lies and why no robot did it."""
    x, y = np.mean(piece["path"], axis=0)
    if piece["state"] == "stranded":
        why = "stranded: no robot left with charge"
    elif piece["blocked_by"]:
        why = f"behind {piece['blocked_by']}'s body"
    else:
        why = f"tried by {', '.join(piece['tried'])}"
    return (
        f"not reached: {piece['id']}, {piece['area_m2']:.2f} m² around ({x:.1f}, {y:.1f}) ({why})"
    )
