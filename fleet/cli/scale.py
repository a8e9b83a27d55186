"""`fleet bench scale`: what a fleet costs as it grows, robot count by robot count."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from fleet.cli.common import _fail, print_result, progress_line, stamped_dir, world_file
from fleet.cli.help_text import reflow
from fleet.cli.options import JsonOpt, SeedOpt, WorldsOpt


def _robot_counts(text: str) -> list[int]:
    """``3,6,12,20`` as counts; exits naming ``--robots`` when one is not a whole number >= 1."""
    counts = []
    for part in (p.strip() for p in text.split(",") if p.strip()):
        if not part.isdigit() or int(part) < 1:
            _fail(f"--robots: {part!r} is not a robot count (a whole number >= 1)")
        counts.append(int(part))
    if not counts:
        _fail("--robots: no robot count given")
    return counts


RobotCountsOpt = Annotated[
    str, typer.Option("--robots", "-n", help="Comma-separated robot counts, one run each.")
]
WindowOpt = Annotated[
    float,
    typer.Option(
        "--window", help="Sim seconds, from the job's first award, the cost is measured over."
    ),
]
ToEndOpt = Annotated[
    bool,
    typer.Option(
        "--to-the-end",
        help="Run each fleet on to its end and report coverage, repetition, makespan and "
        "contacts (without it each run is stopped at the window's end).",
    ),
]
ConfigOpt = Annotated[
    Path | None,
    typer.Option(
        "--config",
        help="Parameter file every run uses (its `fleet up --config`); default: the "
        "built-in configs/fleet.yaml.",
    ),
]
RunRootOpt = Annotated[
    Path | None,
    typer.Option(
        "--run-root", help="Where each run's dir goes (default: runs/bench-scale-<time>)."
    ),
]


def bench_scale(
    worlds: WorldsOpt = "home",
    robots: RobotCountsOpt = "3,6,12,20",
    window: WindowOpt = 60.0,
    to_end: ToEndOpt = False,
    seed: SeedOpt = 0,
    config: ConfigOpt = None,
    run_root: RunRootOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Run `fleet up --headless --until-done --speed 0` with each robot count on each world and
    report what the fleet costs as it grows.

    Over a window of --window sim seconds from the job's first award (the first plan is not
    in it): the real-time factor (sim s per wall s), each agent's CPU per scan (its CPU
    seconds, from /proc/PID/stat, over the scans of the window at lidar.rate_hz: median and
    largest over the agents), the cores the whole run kept busy, the coordinator's share of
    a core, resident memory per agent (median) and of the coordinator. Over the whole run:
    the coordinator's time per auction lot and per round of planned transits (its `auction`
    and `transits` events). With --to-the-end also coverage, makespan and contacts from each
    run's report.json. Progress goes to stderr; the result also to RUN_ROOT/bench.json after
    every run, and each run's dir keeps its logs.

    Examples: `fleet bench scale --worlds home --robots 3,6,12,20`;
    `fleet bench scale --worlds ../shared/data/maps/cob_ipa_apartment.yaml --robots 6,20
    --to-the-end`; `fleet bench scale --robots 3 --window 120 --config my-fleet.yaml --json`.
    """
    from fleet.bench.scale import Settings, run_bench, table_lines
    from fleet.config import ConfigError
    from fleet.params import load_fleet_config

    counts = _robot_counts(robots)
    if not (window > 0 and math.isfinite(window)):
        _fail(f"--window must be a finite number > 0, got {window}")
    try:
        cfg = load_fleet_config(config)
    except ConfigError as e:
        _fail(f"--config: {e}")
    options = ("--config", str(config.resolve())) if config is not None else ()
    chosen = [
        (Path(w.strip()).stem, world_file(w.strip(), "--worlds"))
        for w in worlds.split(",")
        if w.strip()
    ]
    if not chosen:
        _fail("--worlds: no world given")
    root = stamped_dir(run_root, "bench-scale-%Y%m%d-%H%M%S")
    settings = Settings(seed, window, to_end, cfg.lidar.rate_hz, options)
    result = run_bench(root, chosen, counts, settings, progress_line)
    print_result(result, as_json, table_lines)


def register(
    app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app: typer.Typer
) -> None:
    bench_app.command("scale", help=reflow(bench_scale.__doc__ or ""))(bench_scale)
