"""`fleet bench soak`: a long run of the job, looped, and whether memory, open files and the
run dir stay bounded."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from fleet.cli.common import _fail, print_result, progress_line, stamped_dir, world_file
from fleet.cli.help_text import reflow
from fleet.cli.options import BenchSpeedOpt, JsonOpt, SeedOpt, WorldOpt


def bench_soak(
    robots: Annotated[int, typer.Option("--robots", "-n", help="Robots in the run.")] = 6,
    world: WorldOpt = "home",
    sim_s: Annotated[
        float, typer.Option("--sim-s", help="Sim seconds to run before the fleet is stopped.")
    ] = 3600.0,
    speed: BenchSpeedOpt = 0.0,
    every: Annotated[
        float, typer.Option("--every", help="Sim seconds between two samples.")
    ] = 60.0,
    warmup: Annotated[
        float,
        typer.Option(
            "--warmup-s", help="Sim seconds before the figures are judged (the first 10 min)."
        ),
    ] = 600.0,
    seed: SeedOpt = 0,
    run_dir: Annotated[
        Path | None,
        typer.Option("--run-dir", help="The run's dir (default: runs/bench-soak-<time>)."),
    ] = None,
    as_json: JsonOpt = False,
) -> None:
    """Run `fleet up --headless --loop` (the coordinator starts the job again each time it
    finishes) for SIM_S sim seconds and watch whether the fleet holds its resources.

    Every --every sim seconds: each process's resident memory (VmRSS in /proc/PID/status) and
    open files (/proc/PID/fd), `fleet up`'s own included, the run dir's size and the jobs
    finished; a progress line on stderr each time. At the end, per process: RSS at the
    warm-up's end and at the end, peak, growth, open files min-max; the run dir's size over
    time. Pass or fail against the targets: RSS growth at most 5 % past the warm-up, no growth
    in open files (the later half of the samples past the warm-up opens no more than the
    earlier half), the run dir growing at most 50 MB per sim hour past the warm-up. A run
    whose sim clock stops is given up: each sample is waited for 120 wall seconds at least
    (the first 600), and on while the sim clock moves. Everything also goes to
    RUN_DIR/soak.json at each sample; the run dir keeps fleet up's logs and report.

    Examples: `fleet bench soak --robots 6 --world home --sim-s 3600`;
    `fleet bench soak --robots 2 --world small --sim-s 300 --every 30 --warmup-s 60 --json`.
    """
    from fleet.bench.soak import Targets, run_soak, table_lines

    if robots < 1:
        _fail("--robots must be >= 1")
    for name, value in (("--sim-s", sim_s), ("--every", every)):
        if not (value > 0 and math.isfinite(value)):
            _fail(f"{name} must be a finite number > 0, got {value}")
    if speed < 0 or not math.isfinite(speed):
        _fail(f"--speed must be a finite number >= 0, got {speed}")
    if not 0 <= warmup < sim_s:
        _fail(f"--warmup-s must be >= 0 and less than --sim-s, got {warmup}")
    world_path = world_file(world)
    run_dir = stamped_dir(run_dir, "bench-soak-%Y%m%d-%H%M%S")
    if (run_dir / "coordinator.sqlite").exists():
        _fail(f"--run-dir {run_dir} holds an earlier run; choose a new directory")
    run_dir.mkdir(parents=True, exist_ok=True)

    targets = Targets(warmup_s=warmup)
    result = run_soak(
        run_dir, world_path, robots, seed, speed, sim_s, every, targets, progress_line
    )
    print_result(result, as_json, table_lines)
    if not result["verdict"]["ok"]:
        raise typer.Exit(1)


def register(
    app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app: typer.Typer
) -> None:
    bench_app.command("soak", help=reflow(bench_soak.__doc__ or ""))(bench_soak)
