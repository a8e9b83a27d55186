"""``fleet bench lidar``: rays per second of the simulated lidar (the runner in
fleet.bench.lidar)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from fleet.cli.common import _load
from fleet.cli.options import ConfigOpt, JsonOpt


def register(
    app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app: typer.Typer
) -> None:
    bench_app.command("lidar")(bench_lidar)


def bench_lidar(
    seconds: Annotated[
        float, typer.Option(min=0.05, help="Minimum timing per configuration, in seconds.")
    ] = 1.0,
    beams: Annotated[int, typer.Option(min=1, help="Beams per scan (over 360°).")] = 360,
    range_max: Annotated[float, typer.Option(min=0.1, help="Lidar range in metres.")] = 6.0,
    map_yaml: Annotated[
        Path | None,
        typer.Option(
            "--map",
            exists=True,
            dir_okay=False,
            help="Also time a ROS map_server map (YAML + PGM), e.g. "
            "../shared/data/maps/cob_ipa_apartment.yaml, turned into boundary segments.",
        ),
    ] = None,
    baseline: Annotated[
        bool, typer.Option(help="Also time the brute-force caster (every beam × every segment).")
    ] = True,
    as_json: JsonOpt = False,
    config: ConfigOpt = None,
) -> None:
    """Time sim_server.lidar.cast_scans on furnished synthetic floors.

    Three fixed configurations: 1 robot with 150 segments, 100 robots (each seeing the others'
    discs) with 150 segments, and 1 robot with 5000 segments (with and without a SegmentIndex).
    The simulator needs about 0.54 M rays/s for 3 robots at 50× real time and 0.36 M rays/s for
    100 robots at real time (10 Hz, 360 beams). The brute-force baseline runs in the same
    command, so the speed-up column compares like with like on this machine.
    """
    from rich.console import Console
    from rich.table import Table

    from fleet.bench.lidar import run_bench

    radius = _load(config)[0].robot.radius
    rows = run_bench(radius, beams, range_max, seconds, map_yaml, baseline)
    if as_json:
        summary = {r["config"]: r["rays_per_s"] for r in rows}
        print(json.dumps({"rays_per_s": summary, "runs": rows}))
        return
    table = Table(title=f"lidar cast_scans, {beams} beams, range {range_max} m")
    for col in (
        "config",
        "robots",
        "segments",
        "discs",
        "rays/s",
        "brute force rays/s",
        "speed-up",
    ):
        table.add_column(col, justify="left" if col == "config" else "right")
    for r in rows:
        table.add_row(
            r["config"],
            str(r["robots"]),
            str(r["segments"]),
            str(r["discs"]),
            f"{r['rays_per_s'] / 1e6:.2f} M",
            f"{r['baseline_rays_per_s'] / 1e6:.3f} M" if r["baseline_rays_per_s"] else "-",
            f"{r['speedup']:.1f}×" if r["speedup"] else "-",
        )
    Console().print(table)
