"""`fleet dashboard`: the live view of a running fleet from any terminal; and `fleet bench
dashboard`, what the view costs."""

from __future__ import annotations

import json
import os
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Annotated, Any

import typer

from fleet.cli.common import _bus, _fail, _load
from fleet.cli.help_text import reflow
from fleet.cli.options import ConfigOpt, JsonOpt, ZenohConfigOpt
from fleet.supervisor.ops import STATE_FILE

REDRAW_HZ = 5.0
PLAIN_LINE_S = 5.0
TABLE_READ_S = 1.0


DashboardRunDirOpt = Annotated[
    Path | None,
    typer.Option(
        "--run-dir",
        "-d",
        help="The run dir of the fleet to watch (default: the newest one under runs/ with "
        "a processes.json). Its processes.json gives the router's endpoint, the fleet's "
        "name, and the pids the k and r keys act on.",
    ),
]
DashboardConnectOpt = Annotated[
    list[str] | None,
    typer.Option(
        "--connect",
        "-c",
        help="Zenoh router endpoint to attach to (repeatable), e.g. tcp/10.0.0.5:7447 "
        "(default: the endpoint in the run dir's processes.json); FLEET_CONNECT may hold "
        "them, separated by spaces. Without a run dir the k and r keys are off.",
        envvar="FLEET_CONNECT",
    ),
]
DashboardFleetOpt = Annotated[
    str | None,
    typer.Option(
        "--fleet",
        help="Fleet name, the key prefix fleet/<name>/ (default: the run dir's, else 'default').",
        envvar="FLEET_NAME",
    ),
]


def dashboard(
    run_dir: DashboardRunDirOpt = None,
    connect: DashboardConnectOpt = None,
    fleet: DashboardFleetOpt = None,
    zenoh_config: ZenohConfigOpt = None,
    config: ConfigOpt = None,
    plain: Annotated[
        bool,
        typer.Option("--plain", help="Plain log lines even on a terminal (the default without)."),
    ] = False,
) -> None:
    """Attach to a running fleet and watch it: a map of the floor (walls and furniture,
    cleaned floor, each robot as an arrow of its heading with its number, and the path it
    means to drive), a robot table (liveness, state, task, progress, speed, heartbeat age,
    restarts), coverage with a progress bar and an ETA, the job's events (joined, lost,
    reassigned, contacts, waypoints given up) and messages per second on each key it reads.

    Keys: ↑/↓ select a robot, k kills its agent (SIGTERM, as `fleet kill NAME`), r respawns it
    (as `fleet respawn NAME`), q closes the view and leaves the fleet running. Without a
    terminal (or with --plain) it prints a status line every 5 s and each event as it comes,
    until the fleet stops or Ctrl-C. It reads the bus and commands nothing but those two keys.

    Examples: `fleet dashboard` (the newest run under runs/);
    `fleet dashboard --run-dir runs/20250101-120000`;
    `fleet dashboard --connect tcp/10.0.0.5:7447` (a fleet on another machine).
    """
    from rich.console import Console

    from fleet.dashboard.model import BusFeed
    from fleet.dashboard.term import TerminalView, ViewControl
    from fleet.protocol import DEFAULT_FLEET
    from fleet.supervisor.ops import ProcessActions

    table, run_dir = _run_table(run_dir, connect)
    endpoints = connect or [table.endpoint]  # type: ignore[union-attr]
    name = fleet or (table.fleet if table is not None else DEFAULT_FLEET)
    bus = _bus("dashboard", f"view-{os.getpid()}", endpoints, name, zenoh_config)
    watcher = _watcher(bus, _load(config)[0], name, run_dir)
    feed = BusFeed(bus, watcher)
    actions = ProcessActions(run_dir) if table is not None and run_dir is not None else None
    control = ViewControl(watcher, actions)
    console = Console(stderr=False)
    interactive = not plain and console.is_terminal and sys.stdin.isatty()
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    view = TerminalView(watcher, control, console) if interactive else None
    t0 = time.monotonic()
    where = f" ({run_dir})" if run_dir is not None else ""
    print(f"dashboard: fleet {name} at {' '.join(endpoints)}{where}", file=sys.stderr, flush=True)
    try:
        if view is not None:
            view.start()
        _loop(watcher, feed, view, control, table, run_dir, stop, t0)
    except KeyboardInterrupt:
        pass
    finally:
        if view is not None:
            view.stop()
        control.close()
        feed.close()
        bus.close()
    print(watcher.line(time.monotonic() - t0), file=sys.stderr, flush=True)


def _run_table(run_dir: Path | None, connect: list[str] | None) -> tuple[Any, Path | None]:
    """The process table of ``run_dir`` (by default the newest run's), unless the view attaches
    by ``connect`` alone; exits when there is none. The table (or None) and the run dir."""
    from fleet.rundir import RunDirError, newest_run_dir, read_table

    table = None
    if not connect or run_dir is not None:
        try:
            run_dir = run_dir if run_dir is not None else newest_run_dir()
            table = read_table(run_dir)
        except RunDirError as e:
            _fail(f"{e}; or attach by endpoint: fleet dashboard --connect tcp/HOST:PORT")
    return table, run_dir


def _watcher(bus: Any, cfg: Any, name: str, run_dir: Path | None) -> Any:
    """The fleet ``name`` as the bus shows it (its clock's stamps judged), with the job's
    events so far from the run dir's state file."""
    from fleet.dashboard.model import FleetWatcher
    from fleet.plausible import Bounds, StampWatch
    from fleet.protocol import Clock

    watch = StampWatch(Bounds.of(cfg).clock_step_s, bus.drop_implausible, bus.keys.clock())
    bus.subscribe(bus.keys.clock(), Clock, watch.hear_clock)
    watcher = FleetWatcher(name, cfg.coordinator.heartbeat_timeout_s, watch)
    if run_dir is not None:
        _past_events(watcher, run_dir / STATE_FILE)
    return watcher


def _loop(
    watcher: Any,
    feed: Any,
    view: Any,
    control: Any,
    table: Any,
    run_dir: Path | None,
    stop: threading.Event,
    t0: float,
) -> None:
    """Redraw at REDRAW_HZ (or print plain lines) until q, SIGTERM, or — in plain mode — the
    run's `fleet up` has exited."""
    from fleet.rundir import RunDirError, is_alive, process_state, read_table

    last_table = last_line = -1e9
    table_error = ""
    while not stop.is_set() and not control.quit.is_set():
        tick = time.monotonic()
        feed.pump()
        if view is not None:
            view.draw()
        else:
            for line in watcher.take_events():
                print(f"event: {line}", file=sys.stderr, flush=True)
            if tick - last_line >= PLAIN_LINE_S:
                last_line = tick
                print(watcher.line(tick - t0), file=sys.stderr, flush=True)
        if table is not None and run_dir is not None and tick - last_table >= TABLE_READ_S:
            last_table = tick
            try:
                table = read_table(run_dir)
                table_error = ""
            except RunDirError as e:
                if str(e) != table_error:
                    table_error = str(e)
                    watcher.note("error", table_error)
            watcher.set_restarts({n: p.restarts for n, p in table.processes.items()})
            if not is_alive(process_state(table.up_pid, table.up_cmdline)):
                if view is None:
                    print("fleet up has exited: the fleet is stopped", file=sys.stderr)
                    return
                view.note = "fleet up has exited: the fleet is stopped (q closes the view)"
                table = None
        stop.wait(max(0.0, 1.0 / REDRAW_HZ - (time.monotonic() - tick)))


def _past_events(watcher: Any, state: Path) -> None:
    """The job's events so far, from the coordinator's state file, so a view that attaches
    late starts with them (read before subscribing: a few may be missed, none shown twice)."""
    from fleet.dashboard.model import EVENTS_KEPT
    from fleet.protocol import FleetEvent
    from fleet.supervisor.runner import read_events

    for e in read_events(state)[-EVENTS_KEPT:]:
        watcher.on_event(
            "", FleetEvent(e["sim"], e["wall"], e["kind"], e["robot"], e["task"], e["detail"])
        )


def bench_dashboard(
    robots: Annotated[int, typer.Option("--robots", "-n", help="Robots in the fleet.")] = 10,
    speed: Annotated[float, typer.Option("--speed", help="The fleet's real-time factor.")] = 4.0,
    seconds: Annotated[
        float, typer.Option("--seconds", "-s", help="Wall seconds measured (after a warm-up).")
    ] = 20.0,
    width: Annotated[int, typer.Option("--width", help="Terminal columns drawn.")] = 160,
    height: Annotated[int, typer.Option("--height", help="Terminal rows drawn.")] = 50,
    world: Annotated[str, typer.Option("--world", "-w", help="World the fleet is in.")] = "home",
    as_json: JsonOpt = False,
) -> None:
    """What the dashboard costs: its redraw rate and its CPU share of one core while it
    watches a synthetic fleet of N robots at --speed.

    A router and a synthetic fleet run as two other processes. The fleet publishes what a
    real one does, at the rates of configs/fleet.yaml times --speed: per robot odometry, scans,
    commands, pose and intent, true pose, status and heartbeats; the sim clock and coverage;
    the coordinator's state and events; and it serves the floor plan and the cleaned area.
    This process runs the dashboard as `fleet dashboard` does (ring buffers drained, model,
    view drawn as ANSI text for a --width × --height terminal, written to memory) at
    5 Hz, and reports the redraws per second, CPU seconds per wall second of this process
    (`cpu_percent`, 100 = one core), the frame time (`frame_ms_*`: drain, model, drawing) and
    the messages per second of the control-rate streams it drained (`ring_msgs_per_s`: true
    poses, intents, status, clock).

    Example: `fleet bench dashboard --robots 10 --speed 4 --seconds 20`.
    """
    from fleet.bench.dashboard import measure
    from fleet.supervisor.fleet_processes import StartError

    if not 1 <= robots <= 64 or speed <= 0 or seconds <= 0 or width < 40 or height < 15:
        _fail("--robots must be 1-64, --speed and --seconds > 0, --width >= 40, --height >= 15")
    try:
        result = measure(robots, speed, seconds, width, height, world, REDRAW_HZ)
    except StartError as e:
        _fail(str(e))
    if as_json:
        print(json.dumps(result))
        return
    typer.echo(
        f"{robots} robots at {speed}×, {width}×{height}: {result['redraw_hz']} redraws/s, "
        f"{result['cpu_percent']} % of one core, frame {result['frame_ms_p50']} ms "
        f"(max {result['frame_ms_max']}), {result['ring_msgs_per_s']} control-rate msgs/s in; load "
        f"average {result['load_avg']}"
    )


def register(
    app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app: typer.Typer
) -> None:
    app.command("dashboard", help=reflow(dashboard.__doc__ or ""))(dashboard)
    bench_app.command("dashboard", help=reflow(bench_dashboard.__doc__ or ""))(bench_dashboard)
