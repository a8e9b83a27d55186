"""`fleet up`: the whole fleet as separate processes, with a live view and a report; `fleet
explore`; and `fleet bench sim`. The processes are started, watched and stopped by
`fleet.supervisor.fleet_processes`, shown by `fleet.dashboard.up_view`, and reported on by
`fleet.report.up_report` and `fleet.report.explore_report`: here are the options, their
checks, and the exit statuses."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from fleet.cli.common import _check_deconfliction, _fail, _load, stamped_dir
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
MAX_ROBOTS = 64

if TYPE_CHECKING:
    from fleet.dashboard.up_view import UpView
    from fleet.params import FleetConfig
    from fleet.report.summary import RunRecorder
    from fleet.report.up_report import RunFacts
    from fleet.supervisor.fleet_processes import FleetProcesses, FleetSpec
    from fleet.world import World

UntilDoneOpt = Annotated[
    bool, typer.Option("--until-done", help="Stop once every robot has finished its plan.")
]
UpTimeoutOpt = Annotated[
    float | None,
    typer.Option(
        "--timeout",
        help="Stop after this many wall-clock seconds; with --until-done the exit status is "
        "then 3 (the floor was not finished).",
    ),
]
UpRunDirOpt = Annotated[
    Path | None,
    typer.Option("--run-dir", help="Where logs and the report go (default: runs/<date-time>)."),
]
LoopOpt = Annotated[
    bool,
    typer.Option(
        "--loop",
        help="Start the job again each time it finishes (the floor planned afresh), until "
        "Ctrl-C or --timeout: a long run. Not with --until-done.",
    ),
]
FloorMapOpt = Annotated[
    Path | None,
    typer.Option(
        "--map",
        help="Plan the cleaning on this stored ROS map (map.yaml, as `fleet explore` writes "
        "it, in the world's frame) instead of the world file; the simulator still runs the "
        "world, whose dock and start poses the robots start from. Furniture the robots find "
        "moved in since the map was made is put on it and planned round (`map changed`).",
    ),
]
ExploreFirstOpt = Annotated[
    bool,
    typer.Option(
        "--explore",
        help="First explore the world as `fleet explore` does (into RUN_DIR/explore), then "
        "clean on the map it wrote; report.json's `explored` says what exploring took. "
        "--timeout bounds both together.",
    ),
]
ExploreTimeoutOpt = Annotated[
    float | None,
    typer.Option(
        "--timeout",
        help="Stop after this many wall-clock seconds (exit status 3); the map so far is "
        "written all the same.",
    ),
]
ExploreRunDirOpt = Annotated[
    Path | None,
    typer.Option("--run-dir", help="Where logs and the map go (default: runs/<date-time>)."),
]
UnknownStartOpt = Annotated[
    int,
    typer.Option(
        "--unknown-start",
        min=0,
        help="How many of the robots (the last ones) do not know where they start: each "
        "maps in a frame of its own and takes no work until the coordinator has placed its "
        "map on the merged one (refused, with an `unplaced` event, while no match is "
        "confident). explore.json's `placements` says when and how well.",
    ),
]


@dataclass(frozen=True)
class RunRequest:
    """What `fleet up` and `fleet explore` run, as their options say: ``robots`` robots in
    ``world`` at ``speed`` with noise ``seed`` on the parameters ``config``, into ``run_dir``,
    for at most ``timeout`` wall seconds, shown live unless ``headless``."""

    robots: int
    world: str
    speed: float
    seed: int
    config: Path | None
    run_dir: Path
    timeout: float | None
    headless: bool


@dataclass(frozen=True)
class UpRequest:
    """`fleet up`'s options beyond :class:`RunRequest`'s."""

    run: RunRequest
    until_done: bool
    deconfliction: str | None
    loop: bool
    floor_map: Path | None
    explore_first: bool


def up(
    robots: RobotsOpt = 3,
    world: WorldOpt = "home",
    speed: SpeedOpt = 4.0,
    headless: HeadlessOpt = False,
    until_done: UntilDoneOpt = False,
    timeout: UpTimeoutOpt = None,
    run_dir: UpRunDirOpt = None,
    seed: SeedOpt = 0,
    config: ConfigOpt = None,
    deconfliction: DeconflictionOpt = None,
    loop: LoopOpt = False,
    floor_map: FloorMapOpt = None,
    explore_first: ExploreFirstOpt = False,
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
    run = RunRequest(
        robots, world, speed, seed, config, stamped_dir(run_dir, "%Y%m%d-%H%M%S"), timeout, headless
    )
    request = UpRequest(run, until_done, deconfliction, loop, floor_map, explore_first)
    status, report_failed, floor_map = _clean(request)
    _exit_up(request, status, report_failed, floor_map)


def _check_run(run: RunRequest) -> None:
    if not 1 <= run.robots <= MAX_ROBOTS:
        _fail(f"--robots must be between 1 and {MAX_ROBOTS}, got {run.robots}")
    if run.speed < 0 or not math.isfinite(run.speed):
        _fail(f"--speed must be a finite number >= 0, got {run.speed}")
    if run.timeout is not None and run.timeout <= 0:
        _fail(f"--timeout must be > 0 seconds, got {run.timeout}")


def _starts(w: World, cfg: FleetConfig, robots: int) -> tuple[tuple[float, float, float], ...]:
    try:
        starts = w.start_poses(robots, cfg.robot.radius)
    except ValueError as e:
        _fail(str(e))
    return tuple(starts)


def _make_run_dir(run_dir: Path) -> None:
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        _fail(f"--run-dir {run_dir}: {e.strerror}")


def _clean(request: UpRequest) -> tuple[str, bool, Path | None]:
    """`fleet up`'s checks, the exploring first (with --explore), then the cleaning fleet run
    and reported on; how it ended, whether its report failed, and the map it planned on."""
    from fleet.config import ConfigError, resolve_world
    from fleet.report.up_report import RunFacts
    from fleet.supervisor.fleet_processes import FleetSpec
    from fleet.world import on_stored_map

    run = request.run
    _check_run(run)
    if request.loop and request.until_done:
        _fail("--loop starts the job again when it is done: it cannot stop --until-done")
    if request.floor_map is not None and request.explore_first:
        _fail("--explore makes the map the cleaning is planned on: leave out --map")
    cfg, w = _load(run.config, run.world)
    _check_deconfliction(request.deconfliction)
    starts = _starts(w, cfg, run.robots)
    world_path = str(resolve_world(run.world))
    if (run.run_dir / "coordinator.sqlite").exists():
        # a coordinator started on it would resume that run's job, finished or not
        _fail(
            f"--run-dir {run.run_dir} holds an earlier run (coordinator.sqlite); choose a new "
            "directory, or remove that one"
        )
    _make_run_dir(run.run_dir)
    explored, floor_map, timeout = None, request.floor_map, run.timeout
    if request.explore_first:
        explored, floor_map = _explore_first(cfg, w, run)
        if timeout is not None:
            timeout = max(1.0, timeout - explored["wall_s"])
    if floor_map is not None:
        try:
            on_stored_map(w, floor_map)
        except ConfigError as e:
            _fail(str(e))
    coordinator = ["--deconfliction", request.deconfliction] if request.deconfliction else []
    if request.loop:
        coordinator.append("--loop")
    if floor_map is not None:
        coordinator += ["--map", str(floor_map.resolve())]
    spec = FleetSpec(world_path, starts, run.speed, run.seed, run.config, tuple(coordinator))
    mode = request.deconfliction or cfg.coordinator.deconfliction
    on_map = None if floor_map is None else str(floor_map)
    facts = RunFacts(world_path, run.robots, run.speed, run.seed, mode, on_map, explored)
    status, failed = _clean_and_report(run, spec, cfg, w, facts, request.until_done, timeout)
    return status, failed, floor_map


def _clean_and_report(
    run: RunRequest,
    spec: FleetSpec,
    cfg: FleetConfig,
    w: World,
    facts: RunFacts,
    until_done: bool,
    timeout: float | None,
) -> tuple[str, bool]:
    """The cleaning fleet run, watched until it ends, then its report written and told while
    its processes still run (the simulator answers for it); how it ended, and whether the
    report could not be collected."""
    from fleet.protocol import CoverageImage, CoverageSummary
    from fleet.report.summary import ReportError
    from fleet.report.up_report import end_lines, up_report, write_up_report

    status = "interrupted"
    with ExitStack() as stack:
        try:
            fleet, recorder, view = stack.enter_context(_watched(run, spec, cfg))
            on = "" if facts.floor_map is None else f", planned on {facts.floor_map}"
            typer.echo(
                f"fleet: {run.robots} robots in {w.name}{on} at {run.speed}× — logs in "
                f"{run.run_dir}/",
                err=True,
            )
            status = fleet.watch(view, until_done, timeout)
            view.detach()
            wall_s = time.monotonic() - fleet.t0
            assert fleet.bus is not None
            summary = fleet.ask_sim(fleet.bus.keys.sim_report(), CoverageSummary)
            image = fleet.ask_sim(fleet.bus.keys.coverage_image(), CoverageImage)
            report = up_report(run.run_dir, facts, w, summary, image, view.watcher, status, wall_s)
            write_up_report(run.run_dir, report, recorder, image, cfg.robot.cleaning_width)
            for line in end_lines(report, run.run_dir):
                typer.echo(line, err=True)
        except (TimeoutError, RuntimeError, ReportError) as e:
            typer.secho(
                f"error: could not collect the report: {e}; logs in {run.run_dir}/",
                fg="red",
                err=True,
            )
            return status, True
    return status, False


@contextmanager
def _watched(
    run: RunRequest, spec: FleetSpec, cfg: FleetConfig
) -> Iterator[tuple[FleetProcesses, RunRecorder, UpView]]:
    """The fleet of ``spec`` started into the run dir (stopped by SIGINT, SIGTERM or SIGHUP:
    a closed terminal stops it as Ctrl-C does, report written), with the run's recorder and
    the view on its bus; at the end the recorder closed, then the bus, then every process."""
    from fleet.dashboard.up_view import UpView
    from fleet.plausible import Bounds
    from fleet.report.summary import RunRecorder
    from fleet.supervisor.fleet_processes import FleetProcesses, stop_on_signals

    fleet = FleetProcesses(run.run_dir, spec)
    stop_on_signals(fleet.stop)
    recorder = None
    try:
        bus = fleet.start()
        recorder = RunRecorder(bus, Bounds.of(cfg).clock_step_s, run.run_dir)
        yield fleet, recorder, UpView(bus, cfg, recorder.watch, run.run_dir, run.headless)
    finally:
        if recorder is not None:
            recorder.close()
        fleet.close()


def _exit_up(request: UpRequest, status: str, report_failed: bool, floor_map: Path | None) -> None:
    """Exit with `fleet up`'s status for a run that ended ``status`` (see its help)."""
    from fleet.supervisor.fleet_processes import WRONG_MAP, WRONG_MAP_EXIT

    # the floor was not finished, whether the report could be collected or not
    if status == "timeout" and request.until_done:
        raise typer.Exit(TIMED_OUT_EXIT)
    if report_failed:
        raise typer.Exit(1)
    if status == "incomplete":
        raise typer.Exit(INCOMPLETE_EXIT)
    if status == WRONG_MAP:
        run_dir = request.run.run_dir
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
    timeout: ExploreTimeoutOpt = None,
    run_dir: ExploreRunDirOpt = None,
    seed: SeedOpt = 0,
    config: ConfigOpt = None,
    unknown_start: UnknownStartOpt = 0,
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

    run = RunRequest(
        robots, world, speed, seed, config, stamped_dir(run_dir, "%Y%m%d-%H%M%S"), timeout, headless
    )
    _check_run(run)
    if unknown_start >= robots:
        _fail(
            f"--unknown-start {unknown_start}: at least one of the {robots} robots must know "
            "where it starts, or no map would fix the fleet's frame"
        )
    cfg, w = _load(config, world)
    if unknown_start and cfg.agent.pose_source != "slam":
        _fail("--unknown-start needs agent.pose_source slam: only a SLAM map can be placed")
    report = _exploration(cfg, w, run, unknown_start)
    status, out = report["status"], run.run_dir
    lengths = ", ".join(f"{rid} {m:.1f} m" for rid, m in report["path_length_m"].items())
    typer.echo(
        f"{status} after {report['sim_s']} s sim ({report['wall_s']} s wall): "
        f"free-space IoU {report['free_iou']:.3f}, {report['frontiers']['assigned']} frontiers "
        f"assigned, driven {lengths} — {out / MAP_YAML}, {out / MAP_PNG}, "
        f"{out / EXPLORE_REPORT}, {out / EXPLORE_FIGURE}.png",
        err=True,
    )
    exits = {"done": 0, "incomplete": INCOMPLETE_EXIT, "timeout": TIMED_OUT_EXIT}
    exits |= dict.fromkeys(("stopped", "interrupted"), 130)
    raise typer.Exit(exits.get(status, 1))


def _explore_first(cfg: FleetConfig, w: World, run: RunRequest) -> tuple[dict[str, Any], Path]:
    """`fleet up --explore`'s first part: the world explored into RUN_DIR/explore; what it
    took (for report.json's ``explored``) and the map it wrote. Exits unless the exploring
    finished (every reachable frontier mapped, or only unreachable ones left)."""
    from fleet.coordinator.exploring import MAP_YAML

    into = run.run_dir / "explore"
    report = _exploration(cfg, w, replace(run, run_dir=into))
    if report["status"] not in ("done", "incomplete"):
        _fail(f"exploring ended {report['status']}: no cleaning on a map not finished; see {into}/")
    typer.echo(
        f"explored in {report['sim_s']} s sim (free-space IoU {report['free_iou']:.3f}); "
        f"cleaning on {into / MAP_YAML}",
        err=True,
    )
    keys = ("status", "sim_s", "wall_s", "path_length_m", "known_m2", "free_iou", "walls_within")
    return {k: report[k] for k in keys} | {"dir": "explore"}, into / MAP_YAML


def _exploration(cfg: FleetConfig, w: World, run: RunRequest, unknown_start: int = 0) -> dict:
    """Explore ``w`` as ``run`` says, the last ``unknown_start`` robots not told their start,
    into its run dir (the fleet's processes, their logs, the merged map, map.png,
    explore.json and its picture); explore.json's content."""
    from fleet.config import resolve_world
    from fleet.coordinator.exploring import MAP_YAML
    from fleet.report.explore_report import write_explore_report
    from fleet.supervisor.fleet_processes import FleetSpec, StartError

    starts = _starts(w, cfg, run.robots)
    world_path = str(resolve_world(run.world))
    if (run.run_dir / "coordinator.sqlite").exists() or (run.run_dir / MAP_YAML).exists():
        _fail(f"--run-dir {run.run_dir} holds an earlier run; choose a new directory")
    _make_run_dir(run.run_dir)
    explore = ("--explore", str(run.run_dir))
    spec = FleetSpec(world_path, starts, run.speed, run.seed, run.config, explore, unknown_start)
    status = "interrupted"
    try:
        with _watched(run, spec, cfg) as (fleet, _, view):
            typer.echo(
                f"fleet: {run.robots} robots exploring {w.name} at {run.speed}× — {run.run_dir}/",
                err=True,
            )
            status = fleet.watch(view, True, run.timeout)
            view.detach()
            sim_s = view.job_sim_s()
    except StartError as e:
        _fail(str(e))
    if not (run.run_dir / MAP_YAML).exists():
        _fail(f"no map was written (no robot reported its map); logs in {run.run_dir}/")
    wall_s = time.monotonic() - fleet.t0
    return write_explore_report(run.run_dir, cfg, w, starts, unknown_start, status, sim_s, wall_s)


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
    from fleet.bench.sim import run_bench

    if robots < 1 or seconds <= 0:
        _fail("--robots must be >= 1 and --seconds > 0")
    cfg, w = _load(config, world)
    try:
        starts = w.start_poses(robots, cfg.robot.radius, spacing=2 * cfg.robot.radius + 0.06)
    except ValueError as e:
        _fail(str(e))
    result = run_bench(w, cfg, starts, seconds)
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
