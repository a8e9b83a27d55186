"""The ``fleet`` command line: run the fleet, its processes, planners and benchmarks.

Command groups live in their own modules (``fleet/cli_*.py``), each with a ``register``
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
    from fleet import cli_processes

    cli_processes.register(app, plan_app, bench_app, slam_app)
    from fleet import cli_lidar

    cli_lidar.register(app, plan_app, bench_app, slam_app)
    from fleet import cli_mapf

    cli_mapf.register(app, plan_app, bench_app, slam_app)
    from fleet import cli_slam

    cli_slam.register(app, plan_app, bench_app, slam_app)
    from fleet import cli_dwa

    cli_dwa.register(app, plan_app, bench_app, slam_app)
    from fleet import cli_coverage

    cli_coverage.register(app, plan_app, bench_app, slam_app)
    from fleet import cli_ops

    cli_ops.register(app, plan_app, bench_app, slam_app)
    from fleet import cli_recovery

    cli_recovery.register(app, plan_app, bench_app, slam_app)
    from fleet import cli_dashboard

    cli_dashboard.register(app, plan_app, bench_app, slam_app)
    from fleet import cli_fleet_bench

    cli_fleet_bench.register(app, plan_app, bench_app, slam_app)
    from fleet import cli_report

    cli_report.register(app, plan_app, bench_app, slam_app)
    from fleet import cli_certs

    cli_certs.register(app, plan_app, bench_app, slam_app)
    from fleet.help_text import reflow_commands

    reflow_commands(app)


_register_all()


def main() -> None:
    app()


if __name__ == "__main__":
    main()
