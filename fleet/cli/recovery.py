"""`fleet bench recovery`: failure detection, reassignment and what failures cost the job;
`fleet bench chaos`: random faults in real runs, and whether the job survives them."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from fleet.cli.common import _fail, print_result, progress_line, stamped_dir, world_file
from fleet.cli.help_text import reflow
from fleet.cli.options import JsonOpt, RunRobotsOpt, WorldOpt


def bench_recovery(
    world: WorldOpt = "home",
    robots: RunRobotsOpt = 3,
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
    as_json: JsonOpt = False,
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

    _check_robots(robots)
    if kills < 0:
        _fail("--kills must be >= 0")
    _check_sweep(sweep, respawn_after)
    world_path = world_file(world)
    root = stamped_dir(run_root, "bench-recovery-%Y%m%d-%H%M%S")

    result = run_bench(
        root, world_path, robots, seed, kills, scenarios, progress_line, sweep, respawn_after
    )
    print_result(result, as_json, table_lines)


def _check_robots(robots: int) -> None:
    if robots < 2:
        _fail("--robots must be >= 2: a lost robot's work needs another robot to go to")


def _check_sweep(sweep: int, respawn_after: float | None) -> None:
    if sweep < 0:
        _fail("--sweep must be >= 0")
    if respawn_after is not None and (sweep == 0 or respawn_after < 0):
        _fail("--respawn-after needs --sweep N and a time >= 0")


def bench_chaos(
    runs: Annotated[int, typer.Option("--runs", help="Runs with faults (each a whole job).")] = 5,
    faults: Annotated[
        int, typer.Option("--faults", help="Faults per run, at random sim moments (0: none).")
    ] = 5,
    world: WorldOpt = "small",
    robots: RunRobotsOpt = 3,
    seed: Annotated[
        int,
        typer.Option(
            "--seed",
            help="Sensor-noise seed of every run; run k draws its faults from (seed, k).",
        ),
    ] = 0,
    rogue: Annotated[
        bool,
        typer.Option(
            "--rogue",
            help="Also run a rogue client from each job's first auction to its end (with "
            "--faults 0: what implausible and fuzzed messages alone cost a run).",
        ),
    ] = False,
    base_makespan: Annotated[
        float | None,
        typer.Option(
            "--base-makespan",
            help="The no-fault run's makespan (sim s), if known: the no-fault run is skipped.",
        ),
    ] = None,
    run_root: Annotated[
        Path | None,
        typer.Option(
            "--run-root", help="Where each run's dir goes (default: runs/bench-chaos-<time>)."
        ),
    ] = None,
    as_json: JsonOpt = False,
) -> None:
    """Throw faults at real fleets and see whether the job survives: a no-fault run, then RUNS
    runs of `fleet up --speed 0 --until-done`, each with FAULTS faults at random sim moments
    (between 10 % and 80 % of the no-fault makespan) drawn from a seeded RNG among: SIGKILL of
    an agent then `fleet respawn`; SIGSTOP of an agent, SIGCONT 5 s later; SIGKILL of the
    coordinator, respawned 2 s later; a rogue client on the run's router that for 10 s sends
    fuzzed payloads on every key class and well-formed messages no receiver may believe
    (stamps far ahead of the sim clock, positions no robot can reach, scans not from the
    lidar, commands beyond the robot's speeds, senders not in the job). Router restarts are
    not among them: `fleet up` stops the fleet when its router dies.

    Per run: finished or not, status, coverage, makespan against the no-fault run, tasks lost
    (never done, not left out as blocked or unreachable), per fault its detection (signal →
    the coordinator's `lost`) and reassignment (`lost` → its work re-sold) times, or the
    restarted coordinator's time to `resumed`; processes that exited other than by the bench's
    SIGKILLs, and the logs that hold tracebacks. A table on stdout (progress on stderr),
    `--json` for scripts; everything also goes to RUN_ROOT/bench.json.

    Examples: `fleet bench chaos --runs 5 --faults 5 --world small`;
    `fleet bench chaos --runs 1 --faults 0 --rogue --json` (a clean run against one with a
    rogue throughout).
    """
    from fleet.bench.chaos import run_bench, table_lines

    if runs < 1:
        _fail("--runs must be >= 1")
    if faults < 0:
        _fail("--faults must be >= 0")
    _check_robots(robots)
    world_path = world_file(world)
    root = stamped_dir(run_root, "bench-chaos-%Y%m%d-%H%M%S")

    if base_makespan is not None and base_makespan <= 0:
        _fail("--base-makespan must be > 0")
    result = run_bench(
        root, world_path, robots, seed, runs, faults, rogue, progress_line, base_makespan
    )
    print_result(result, as_json, table_lines)


def register(
    app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app: typer.Typer
) -> None:
    bench_app.command("recovery", help=reflow(bench_recovery.__doc__ or ""))(bench_recovery)
    bench_app.command("chaos", help=reflow(bench_chaos.__doc__ or ""))(bench_chaos)
