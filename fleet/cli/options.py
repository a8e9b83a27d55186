"""The options several command modules share, each declared once as an ``Annotated`` alias:
where the fleet is (bus, fleet name, Zenoh config), what it runs (world, config, robots, speed,
seed, deconfliction) and how a command reports (``--headless``, ``--json``). A command gives
its own default: ``robots: RobotsOpt = 3``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

ConnectOpt = Annotated[
    list[str] | None,
    typer.Option(
        "--connect",
        "-c",
        help="Zenoh router endpoint to connect to (repeatable), e.g. tcp/192.168.1.5:7447; "
        "FLEET_CONNECT may hold them, separated by spaces.",
        envvar="FLEET_CONNECT",
    ),
]
FleetOpt = Annotated[
    str,
    typer.Option("--fleet", help="Fleet name: the key prefix fleet/<name>/.", envvar="FLEET_NAME"),
]
ConfigOpt = Annotated[
    Path | None,
    typer.Option(
        "--config",
        help="Parameter file (default: the built-in configs/fleet.yaml).",
        envvar="FLEET_CONFIG",
    ),
]
ZenohConfigOpt = Annotated[
    Path | None,
    typer.Option(
        "--zenoh-config",
        help="Zenoh config file (JSON5) under the fleet's own settings, e.g. the TLS files, user "
        "and password for a secured router that `fleet certs DIR` wrote as DIR/<user>.json5.",
        envvar="FLEET_ZENOH_CONFIG",
    ),
]
WorldOpt = Annotated[
    str,
    typer.Option(
        "--world",
        "-w",
        help="World YAML or ROS map_server YAML, or a built-in world name (home, small).",
        envvar="FLEET_WORLD",
    ),
]
# the benches over several worlds (`fleet bench fleet`, `follow`, `scale`)
WorldsOpt = Annotated[
    str,
    typer.Option(
        "--worlds",
        "-w",
        help="Comma-separated worlds: built-in names (home, small), world YAML files, or ROS "
        "map_server YAML files.",
    ),
]
DeconflictionOpt = Annotated[
    str | None,
    typer.Option(
        "--deconfliction",
        help="Transits between tasks: local (robots give way by their intents only), "
        "prioritized (planned in space and time with priorities, CBS where they fail) or cbs "
        "(planned jointly); robots keep the plan's order through shared cells. Default: "
        "coordinator.deconfliction of the config (local).",
    ),
]

# a fleet run here (`fleet up`, `fleet explore`, and `fleet sim` for --speed and --seed)
RobotsOpt = Annotated[int, typer.Option("--robots", "-n", help="Number of robot agents.")]
SpeedOpt = Annotated[
    float,
    typer.Option("--speed", help="Real-time factor; 0 runs as fast as the agents keep up."),
]
SeedOpt = Annotated[int, typer.Option("--seed", help="Seed for the simulator's sensor noise.")]
HeadlessOpt = Annotated[
    bool, typer.Option("--headless", help="Plain log lines instead of the live table.")
]

# the benches that run whole fleets (`fleet bench fleet`, `explore`, `soak`, `recovery`, ...)
RunRobotsOpt = Annotated[int, typer.Option("--robots", "-n", help="Robots in each run.")]
BenchSpeedOpt = Annotated[
    float,
    typer.Option("--speed", help="Sim seconds per wall second; 0 runs as fast as it can."),
]
RunTimeoutOpt = Annotated[
    float, typer.Option("--timeout", help="Wall seconds a run may take before it is stopped.")
]

JsonOpt = Annotated[bool, typer.Option("--json", help="Print one JSON object.")]
