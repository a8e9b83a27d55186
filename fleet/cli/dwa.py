"""``fleet bench dwa``: how long one DWA control step takes with a full lidar scan (the runner
in fleet.bench.dwa)."""

from __future__ import annotations

import json
from typing import Annotated

import typer

from fleet.cli.options import JsonOpt


def register(app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app) -> None:
    bench_app.command("dwa")(bench_dwa)


def bench_dwa(
    calls: Annotated[int, typer.Option(min=10, help="Timed calls, after 20 warm-up calls.")] = 500,
    beams: Annotated[
        int, typer.Option(min=1, help="Lidar points handed to the planner as obstacles.")
    ] = 360,
    as_json: JsonOpt = False,
) -> None:
    """Time one DWA step (planners/dwa.py) with the parameters from configs/fleet.yaml.

    The robot drives at 0.3 m/s, 0.2 rad/s in a furnished room; every lidar point is an obstacle.
    Reports the median and 95th-percentile time per call, rollouts (sampled trajectories) per
    second, and the clearance query alone with a cKDTree against a dense numpy distance matrix
    (the baseline the planner's choice was measured against).
    """
    from fleet.bench.dwa import run_bench
    from fleet.params import load_fleet_config

    result = run_bench(load_fleet_config(), calls, beams)
    if as_json:
        typer.echo(json.dumps(result))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title="DWA control step")
    table.add_column("metric")
    table.add_column("value", justify="right")
    for key, value in result.items():
        table.add_row(key, str(value))
    Console().print(table)
