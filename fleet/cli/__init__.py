"""The ``fleet`` command line: run the fleet, its processes, planners and benchmarks.

Command groups live in their own modules (``fleet/cli/*.py``), each with a ``register``
function that adds its commands to the groups below. Heavy imports happen inside commands, so
``fleet --help`` stays fast.
"""

from __future__ import annotations

import typer

app = typer.Typer(
    help="fleet: a multi-robot cleaning system over Eclipse Zenoh.\n\n"
    "Start here: `fleet up --robots 3` runs a simulated home with three robots until the floor "
    "is clean and writes a report.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
plan_app = typer.Typer(
    help="Offline planners: coverage paths, multi-agent paths.", no_args_is_help=True
)
bench_app = typer.Typer(help="Benchmarks that measure speed and quality.", no_args_is_help=True)
slam_app = typer.Typer(help="SLAM tools: replay recorded logs.", no_args_is_help=True)
app.add_typer(plan_app, name="plan")
app.add_typer(bench_app, name="bench")
app.add_typer(slam_app, name="slam")


def _register_all() -> None:
    """Each command module adds its commands; one line per module."""
    from fleet.cli import up

    up.register(app, plan_app, bench_app, slam_app)
    from fleet.cli import processes

    processes.register(app, plan_app, bench_app, slam_app)
    from fleet.cli import lidar

    lidar.register(app, plan_app, bench_app, slam_app)
    from fleet.cli import mapf

    mapf.register(app, plan_app, bench_app, slam_app)
    from fleet.cli import slam

    slam.register(app, plan_app, bench_app, slam_app)
    from fleet.cli import dwa

    dwa.register(app, plan_app, bench_app, slam_app)
    from fleet.cli import coverage

    coverage.register(app, plan_app, bench_app, slam_app)
    from fleet.cli import ops

    ops.register(app, plan_app, bench_app, slam_app)
    from fleet.cli import recovery

    recovery.register(app, plan_app, bench_app, slam_app)
    from fleet.cli import dashboard

    dashboard.register(app, plan_app, bench_app, slam_app)
    from fleet.cli import fleet_bench

    fleet_bench.register(app, plan_app, bench_app, slam_app)
    from fleet.cli import deconfliction

    deconfliction.register(app, plan_app, bench_app, slam_app)
    from fleet.cli import report

    report.register(app, plan_app, bench_app, slam_app)
    from fleet.cli import certs

    certs.register(app, plan_app, bench_app, slam_app)
    from fleet.cli import soak

    soak.register(app, plan_app, bench_app, slam_app)
    from fleet.cli import auction

    auction.register(app, plan_app, bench_app, slam_app)
    from fleet.cli import scale

    scale.register(app, plan_app, bench_app, slam_app)
    from fleet.cli.help_text import reflow_commands

    reflow_commands(app)


_register_all()


def main() -> None:
    app()
