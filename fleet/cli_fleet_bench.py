"""`fleet bench fleet`: what whole fleets deliver on the floor, over worlds and seeds."""

from __future__ import annotations

import json
import math
import sys
from datetime import datetime
from pathlib import Path
from typing import Annotated

import typer

from fleet.cli_processes import _fail
from fleet.help_text import reflow


def _seeds(text: str) -> list[int]:
    """``0,1,2`` or ``0-4`` (inclusive), or a mix: ``0-2,7``."""
    out: list[int] = []
    for part in text.split(","):
        part = part.strip()
        lo, sep, hi = part.partition("-")
        try:
            out += list(range(int(lo), int(hi) + 1)) if sep else [int(part)]
        except ValueError:
            _fail(f"--seeds: {part!r} is not a seed or a range like 0-4")
    if not out:
        _fail("--seeds: no seed given")
    return out


def bench_fleet(
    worlds: Annotated[
        str,
        typer.Option(
            "--worlds",
            "-w",
            help="Comma-separated worlds: built-in names (home, small), world YAML files, or "
            "ROS map_server YAML files.",
        ),
    ] = "home",
    seeds: Annotated[
        str, typer.Option("--seeds", help="Seeds of the runs: 0,1,2 or 0-4 or a mix.")
    ] = "0-4",
    robots: Annotated[int, typer.Option("--robots", "-n", help="Robots in every run.")] = 3,
    speed: Annotated[
        float,
        typer.Option("--speed", help="Sim seconds per wall second; 0 runs as fast as it can."),
    ] = 0.0,
    timeout: Annotated[
        float, typer.Option("--timeout", help="Wall seconds a run may take before it is stopped.")
    ] = 1200.0,
    run_root: Annotated[
        Path | None,
        typer.Option(
            "--run-root", help="Where each run's dir goes (default: runs/bench-fleet-<time>)."
        ),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Run `fleet up --headless --until-done` for every world and seed, and report what the
    fleet delivered on the floor, as the simulator measured it.

    Per run and as medians per world: coverage of the cleanable floor, repetition, makespan,
    the makespan the coordinator's first allocation priced (and the ratio), wall time,
    real-time factor, contacts (robot–wall and robot–robot), waypoints given up, and where the
    robots' time went (sweeping, transit, turning in place, giving way, escaping, idle). Each
    run's dir keeps its report.json, report.png and logs. Progress goes to stderr; the result
    is also written to RUN_ROOT/bench.json after every run.

    Examples: `fleet bench fleet --worlds home --seeds 0-4`;
    `fleet bench fleet --worlds small,home --seeds 0,1 --json`;
    `fleet bench fleet --worlds ../shared/data/maps/cob_ipa_apartment.yaml --seeds 0-2`.
    """
    from fleet.config import ConfigError, resolve_world
    from fleet.fleet_bench import run_bench, table_lines

    if robots < 1:
        _fail("--robots must be >= 1")
    if speed < 0 or not math.isfinite(speed):
        _fail(f"--speed must be a finite number >= 0, got {speed}")
    if timeout <= 0:
        _fail("--timeout must be > 0")
    chosen = []
    for name in (w.strip() for w in worlds.split(",") if w.strip()):
        try:
            path = resolve_world(name)
        except ConfigError as e:
            _fail(f"--worlds: {e}")
        chosen.append((Path(name).stem, str(path)))
    if not chosen:
        _fail("--worlds: no world given")
    root = run_root or Path("runs") / datetime.now().strftime("bench-fleet-%Y%m%d-%H%M%S")

    def progress(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    result = run_bench(root, chosen, _seeds(seeds), robots, speed, timeout, progress)
    if as_json:
        print(json.dumps(result))
    else:
        typer.echo("\n".join(table_lines(result)))


def register(
    app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app: typer.Typer
) -> None:
    bench_app.command("fleet", help=reflow(bench_fleet.__doc__ or ""))(bench_fleet)
