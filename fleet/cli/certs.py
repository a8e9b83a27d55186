"""`fleet certs DIR`: a CA, certificates, passwords and configs for a secured fleet router."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from fleet.cli.common import _fail


def certs(
    lab_dir: Annotated[
        Path,
        typer.Argument(
            metavar="DIR", help="Directory to write into (made if missing).", show_default=False
        ),
    ],
    robots: Annotated[
        int,
        typer.Option(
            "--robots", "-n", min=1, help="Robots to make users for: robot-0 ... robot-(N-1)."
        ),
    ] = 3,
    host: Annotated[
        list[str] | None,
        typer.Option(
            "--host",
            help="Name or address the router is reached at, put in its certificate besides "
            "localhost and 127.0.0.1 (repeatable), e.g. --host lab-router --host 10.0.0.5.",
        ),
    ] = None,
    days: Annotated[
        int, typer.Option("--days", min=1, help="How long the certificates are valid.")
    ] = 825,
) -> None:
    """Make what a lab needs to run the fleet through a secured router: TLS, a user and
    password per process, and an access-control list that lets each process send only what
    its role sends (only the simulator scans and odometry, only robot R robot R's cmd_vel,
    only the coordinator plans and awards; robots never see truth).

    Writes DIR/ca.pem and ca.key (a CA for this lab), router.pem and router.key, credentials.txt
    (user:password lines), router.json5 (the router's config) and one client config per user:
    sim.json5, coordinator.json5, dashboard.json5, robot-0.json5, ... Keys and passwords are
    readable by their owner only; copy each host only the files its processes use (ca.pem and
    their own USER.json5). Running it again makes new keys and passwords.

    Then: `fleet router --listen tls/0.0.0.0:7447 --zenoh-config DIR/router.json5`, and e.g.
    `fleet agent --id robot-0 --connect tls/ROUTER:7447 --zenoh-config DIR/robot-0.json5`.
    configs/zenoh/router-secure.json5 is the same router config for three robots with DIR=lab.
    """
    from fleet.security import LabError, make_lab

    try:
        lab = make_lab(lab_dir, robots, host or (), days)
    except LabError as e:
        _fail(str(e))
    typer.echo(f"wrote a CA, the router's certificate and {len(lab.users)} users to {lab.dir}/")
    typer.echo(
        f"  router: fleet router --listen tls/0.0.0.0:7447 --zenoh-config {lab.router_config}"
    )
    for user, path in lab.client_configs.items():
        typer.echo(f"  {user:<12} --zenoh-config {path}")


def register(
    app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app: typer.Typer
) -> None:
    app.command("certs")(certs)
