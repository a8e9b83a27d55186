"""`fleet report RUN_DIR`: draw a finished run's pictures again from what it wrote."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from fleet.cli.common import _fail


def report(
    run_dir: Annotated[
        Path,
        typer.Argument(
            metavar="RUN_DIR",
            help="A run dir written by `fleet up` (runs/<date-time> by default).",
            show_default=False,
        ),
    ],
) -> None:
    """Draw a run's report pictures again from the files the run wrote, and print its figures.

    Reads RUN_DIR/report.json (figures, events), coverage.npz (the final cleaning grid),
    tracks.csv (true tracks), coverage.csv (coverage over time) and collisions.csv.

    Writes report.png and report.svg (the floor: cleaned cells shaded by passes, missed
    cleanable cells in red, each robot's track in its live-view colour with its id, a scale bar
    in metres, a legend, the figures) and coverage.png and coverage.svg (coverage over sim
    time, the fleet's and each robot's, with joins, losses, reassignments and contacts marked).

    A run dir of `fleet explore` (explore.json, no report.json): reads explore.json, map.yaml,
    tracks.csv and coordinator.sqlite, and writes explore.png and explore.svg (the merged map,
    each robot's track and the frontier goals it was sold, the known area and the frontiers over
    sim time).

    Example: `fleet report runs/20250101-120000`. A missing or damaged file is named in the
    error (exit status 2).
    """
    from fleet.report.exploration import EXPLORE_REPORT
    from fleet.report.explore_figure import redraw_explore
    from fleet.report.figures import render_report
    from fleet.report.summary import REPORT_FILE, ReportError, load_run

    if (run_dir / EXPLORE_REPORT).exists() and not (run_dir / REPORT_FILE).exists():
        try:
            explored, written = redraw_explore(run_dir)
        except ReportError as e:
            _fail(str(e))
        typer.echo(
            f"{explored['status']}: {explored['known_m2']:.1f} m² known in "
            f"{explored['sim_s']:.0f} s sim, free-space IoU {explored['free_iou']:.3f}"
        )
        for path in written:
            typer.echo(f"wrote {path}")
        return
    try:
        data = load_run(run_dir)
    except ReportError as e:
        _fail(str(e))
    written = render_report(data)
    r = data.report
    makespan = r.get("makespan_s")
    typer.echo(
        f"{r['status']}: coverage {100 * r['coverage']:.1f} %, repetition "
        f"{100 * r['repetition']:.1f} %, makespan "
        f"{'not done' if makespan is None else f'{makespan} s sim'}, {len(data.robots)} robots"
    )
    for path in written:
        typer.echo(f"wrote {path}")


def register(
    app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app: typer.Typer
) -> None:
    app.command("report")(report)
