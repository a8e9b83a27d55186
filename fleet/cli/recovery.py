"""`fleet bench recovery`: failure detection, reassignment and what failures cost the job."""

from __future__ import annotations

import json
import sys
from datetime import datetime
from pathlib import Path
from typing import Annotated

import typer

from fleet.cli.common import WorldOpt, _fail
from fleet.cli.help_text import reflow


def bench_recovery(
    world: WorldOpt = "home",
    robots: Annotated[int, typer.Option("--robots", "-n", help="Robots in each run.")] = 3,
    seed: Annotated[int, typer.Option("--seed", help="Sensor-noise seed of every run.")] = 0,
    kills: Annotated[
        int,
        typer.Option(
            "--kills",
            help="SIGKILL trials (and as many SIGSTOP trials) for the latency figures; 0 skips "
            "them.",
        ),
    ] = 10,
    scenarios: Annotated[
        bool,
        typer.Option(
            "--scenarios/--no-scenarios",
            help="Also run the four whole-run scenarios (no failure; robot-1 killed at a third; "
            "killed and respawned; coordinator killed and restarted).",
        ),
    ] = True,
    sweep: Annotated[
        int,
        typer.Option(
            "--sweep",
            help="Also kill robot-1 at this many moments spread over the no-failure run's "
            "makespan, one run each, and report each moment (0: none; 10 is the usual).",
        ),
    ] = 0,
    respawn_after: Annotated[
        float | None,
        typer.Option(
            "--respawn-after",
            help="With --sweep: respawn robot-1 this many sim seconds after each kill.",
        ),
    ] = None,
    run_root: Annotated[
        Path | None,
        typer.Option(
            "--run-root", help="Where each run's dir goes (default: runs/bench-recovery-<time>)."
        ),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Measure recovery on real fleets: every run is `fleet up --speed 0 --until-done`, and
    failures are real signals to its processes.

    Prints detection latency (signal sent → the coordinator's `lost` event) for SIGKILL and
    SIGSTOP, reassignment latency (`lost` → the last of the robot's work auctioned again), and
    per scenario the coverage, makespan (and its ratio to the no-failure run), contacts and
    tasks held twice. Progress goes to stderr; everything is also written to RUN_ROOT/bench.json.

    With `--sweep N`, robot-1 is killed at N moments spread over the job (k / (N + 1) of the
    no-failure makespan), one run each: wherever its body stays, in the way or not. Per moment:
    status, coverage, coverage of the floor not under the body, makespan against the
    no-failure run, contacts, waypoints given up, the robots' escape time and the
    coordinator's stuck events; `--respawn-after S` respawns it S sim seconds after its death.

    Examples: `fleet bench recovery --world small --kills 10`;
    `fleet bench recovery --world home --kills 0 --json` (scenarios only);
    `fleet bench recovery --world small --kills 0 --no-scenarios --sweep 10` (kill anywhere);
    `... --sweep 10 --respawn-after 3`.
    """
    from fleet.bench.recovery import run_bench, table_lines
    from fleet.config import ConfigError, resolve_world

    if robots < 2:
        _fail("--robots must be >= 2: a lost robot's work needs another robot to go to")
    if kills < 0:
        _fail("--kills must be >= 0")
    if sweep < 0:
        _fail("--sweep must be >= 0")
    if respawn_after is not None and (sweep == 0 or respawn_after < 0):
        _fail("--respawn-after needs --sweep N and a time >= 0")
    try:
        world_path = str(resolve_world(world))
    except ConfigError as e:
        _fail(str(e))
    root = run_root or Path("runs") / datetime.now().strftime("bench-recovery-%Y%m%d-%H%M%S")

    def progress(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    result = run_bench(
        root, world_path, robots, seed, kills, scenarios, progress, sweep, respawn_after
    )
    if as_json:
        print(json.dumps(result))
    else:
        typer.echo("\n".join(table_lines(result)))


def register(
    app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app: typer.Typer
) -> None:
    bench_app.command("recovery", help=reflow(bench_recovery.__doc__ or ""))(bench_recovery)
