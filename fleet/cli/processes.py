"""Commands that run one fleet process each: router, sim, agent, coordinator."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from fleet.bus import DEFAULT_ENDPOINT
from fleet.cli.common import _bus, _fail, _load, _setup_logging, _stop_on_signals
from fleet.cli.options import (
    ConfigOpt,
    ConnectOpt,
    DeconflictionOpt,
    FleetOpt,
    SeedOpt,
    SpeedOpt,
    WorldOpt,
    ZenohConfigOpt,
)
from fleet.protocol import DEFAULT_FLEET
from fleet.supervisor.fleet_processes import WRONG_MAP_EXIT

if TYPE_CHECKING:  # imported where they run: `fleet` starts without them
    from fleet.bus import Bus
    from fleet.coordinator.charging import Pose
    from fleet.coordinator.planning import TaskPlanner
    from fleet.coordinator.service import Coordinator
    from fleet.coordinator.store import JobStore
    from fleet.coordinator.transits import TransitPlanner
    from fleet.params import FleetConfig
    from planners.grid import GridMap


def router(
    listen: Annotated[
        list[str] | None,
        typer.Option("--listen", "-l", help="Endpoint to listen on (repeatable)."),
    ] = None,
    zenoh_config: ZenohConfigOpt = None,
) -> None:
    """Run a Zenoh router, so fleet processes on this or other machines can meet.

    Example: `fleet router --listen tcp/0.0.0.0:7447`, then on each machine
    `fleet agent --id robot-0 --connect tcp/<router-host>:7447`.

    Secured (TLS, a password per process, an access-control list): `fleet certs lab`, then
    `fleet router --listen tls/0.0.0.0:7447 --zenoh-config lab/router.json5` and each process
    with `--connect tls/<router-host>:7447 --zenoh-config lab/<its user>.json5`.
    """
    from fleet.bus import open_router

    _setup_logging("router")
    endpoints = listen or [DEFAULT_ENDPOINT]
    try:
        session = open_router(endpoints, zenoh_config)
    except ValueError as e:
        _fail(str(e))
    except Exception as e:
        _fail(f"cannot listen on {endpoints}: {e}")
    import logging

    logging.getLogger("router").info("Zenoh router listening on %s", ", ".join(endpoints))
    stop = threading.Event()
    _stop_on_signals(stop)
    stop.wait()
    session.close()


def sim(
    world: WorldOpt = "home",
    speed: SpeedOpt = 1.0,
    seed: SeedOpt = 0,
    connect: ConnectOpt = None,
    zenoh_config: ZenohConfigOpt = None,
    fleet: FleetOpt = DEFAULT_FLEET,
    config: ConfigOpt = None,
    record_carmen: Annotated[
        Path | None,
        typer.Option(
            "--record-carmen",
            help="Write one robot's scans (ROBOTLASER1) and odometry (ODOM) to this CARMEN log, "
            "and its true poses at each scan to FILE.truth.csv; `fleet slam replay FILE` reads it.",
        ),
    ] = None,
    record_robot: Annotated[
        str | None,
        typer.Option(
            "--record-robot", help="Robot to record (default: the first robot that spawns)."
        ),
    ] = None,
) -> None:
    """Run the world simulator: physics, lidar, odometry, collisions and ground-truth cleaning."""
    import numpy as np

    from sim_server.server import SimServer

    if speed < 0:
        _fail("--speed must be >= 0")
    _setup_logging("sim")
    cfg, w = _load(config, world)
    recorder = None
    if record_carmen is not None:
        from sim_server.recorder import CarmenRecorder

        try:
            recorder = CarmenRecorder(record_carmen, record_robot, comment=f"world {w.name}")
        except OSError as e:
            _fail(f"--record-carmen: cannot write {record_carmen}: {e}")
    bus = _bus("sim", "sim", connect, fleet, zenoh_config)
    starts = np.array([p[:2] for p in w.start_poses(1, cfg.robot.radius)])
    server = SimServer(bus, w, cfg, speed=speed, seed=seed, starts_xy=starts, recorder=recorder)
    _stop_on_signals(server.stop)
    try:
        server.run()
    finally:
        bus.close()
        if recorder is not None:
            recorder.close()


def agent(
    robot_id: Annotated[str, typer.Option("--id", help="Robot id, e.g. robot-0.")],
    start: Annotated[
        str | None,
        typer.Option(
            "--start", help="Spawn pose x,y,theta (m, m, rad); default: see --start-index."
        ),
    ] = None,
    start_index: Annotated[
        int,
        typer.Option(
            "--start-index",
            min=0,
            help="Without --start, spawn at the world's start pose number K (0-based), where "
            "`fleet up` puts robot-K: the world's listed starts, then free poses by the dock.",
        ),
    ] = 0,
    world: WorldOpt = "home",
    connect: ConnectOpt = None,
    zenoh_config: ZenohConfigOpt = None,
    fleet: FleetOpt = DEFAULT_FLEET,
    config: ConfigOpt = None,
    state_dir: Annotated[
        Path | None,
        typer.Option(
            "--state-dir",
            help="Where the robot keeps what a real robot keeps on disk (its SLAM map and last "
            "pose), saved every agent.state_save_s; default: nothing is kept.",
        ),
    ] = None,
    respawn: Annotated[
        bool,
        typer.Option(
            "--respawn",
            help="Rejoin with the robot body already in the world: load the map and pose from "
            "--state-dir and re-localize on the map before taking work.",
        ),
    ] = False,
    unknown_start: Annotated[
        bool,
        typer.Option(
            "--unknown-start",
            help="The robot does not know where it starts (an exploring fleet's late joiner): "
            "the start pose only places its body; its odometry and SLAM start at (0, 0, 0) of "
            "its own frame, and it stands and takes no work until the coordinator has placed "
            "its map on the fleet's merged map. Needs agent.pose_source slam.",
        ),
    ] = False,
) -> None:
    """Run one robot agent: SLAM on its own sensors, bids for tasks, drives them with DWA."""
    from agents.agent import Agent

    _setup_logging(robot_id)
    if not robot_id or "/" in robot_id or "*" in robot_id:
        _fail(f"--id {robot_id!r}: a robot id must be non-empty without '/' or '*'")
    if respawn and state_dir is None:
        _fail("--respawn needs --state-dir: the directory the robot saved its map and pose to")
    pose, cfg = _spawn_pose(start, start_index, world, config)
    if unknown_start and cfg.agent.pose_source != "slam":
        _fail(
            "--unknown-start needs agent.pose_source slam: only a robot's own map can be "
            f"placed on the fleet's (the config has {cfg.agent.pose_source!r})"
        )
    bus = _bus("agent", robot_id, connect, fleet, zenoh_config)
    a = Agent(bus, robot_id, cfg, state_dir, unknown_start=unknown_start)
    _stop_on_signals(a.stop)
    try:
        a.spawn(pose, respawn=respawn)  # type: ignore[arg-type]
        a.run()
    except (TimeoutError, ValueError) as e:
        _fail(f"{robot_id}: {e}")
    finally:
        bus.close()


def _spawn_pose(start: str | None, start_index: int, world: str, config: Path | None):
    """Where the robot spawns (``--start``, else the world's start pose number
    ``--start-index``) and the parameters; exits naming a bad pose."""
    if start is not None:
        try:
            pose = tuple(float(v) for v in start.split(","))
        except ValueError:
            pose = ()
        if len(pose) != 3:
            _fail(f"--start {start!r}: expected x,y,theta, e.g. --start 1.0,0.5,1.57")
        cfg, _ = _load(config)
    else:
        cfg, w = _load(config, world)
        try:
            pose = w.start_poses(start_index + 1, cfg.robot.radius)[start_index]
        except ValueError as e:
            _fail(f"--start-index {start_index}: {e}")
    return pose, cfg


def coordinator(
    robots: Annotated[
        int, typer.Option("--robots", "-n", help="Robots to wait for before planning.")
    ] = 1,
    world: WorldOpt = "home",
    connect: ConnectOpt = None,
    zenoh_config: ZenohConfigOpt = None,
    fleet: FleetOpt = DEFAULT_FLEET,
    config: ConfigOpt = None,
    state: Annotated[
        Path | None,
        typer.Option(
            "--state",
            help="SQLite file that keeps the job (tasks, owners, swept parts, events) as it "
            "changes; a coordinator started on an existing file resumes it.",
        ),
    ] = None,
    deconfliction: DeconflictionOpt = None,
    explore: Annotated[
        Path | None,
        typer.Option(
            "--explore",
            help="Explore instead of cleaning, and write the merged map (map.yaml, map.pgm) "
            "into this directory: the floor plan is not read; the robots' own maps are merged, "
            "and their frontiers auctioned until none is left.",
        ),
    ] = None,
    loop: Annotated[
        bool,
        typer.Option(
            "--loop", help="When the job finishes, plan the floor again and start the next job."
        ),
    ] = False,
    floor_map: Annotated[
        Path | None,
        typer.Option(
            "--map",
            help="Plan on this stored ROS map (map.yaml, as `fleet explore` writes it, in the "
            "world's frame) instead of the world's floor plan; the dock and starts stay the "
            "world's. When most robots' own maps do not match it (another building), the "
            "coordinator stops with a message naming the file and exit status 5; once they "
            "match, furniture they show moved in since is put on it and planned round.",
        ),
    ] = None,
) -> None:
    """Run the coordinator: cuts the floor into tasks, auctions them to the live robots,
    re-auctions the work of a robot that is lost, and sends each robot its plans. With
    --explore it auctions the frontiers of the robots' merged maps instead; with --map it
    plans on a stored map instead of the world's floor plan."""
    if robots < 1:
        _fail("--robots must be >= 1")
    _setup_logging("coordinator")
    cfg, w, docks, planner, transits, store = _coordinator_job(
        robots, world, fleet, config, state, deconfliction, explore, floor_map
    )
    if explore is not None and loop:
        _fail("--loop and --explore do not go together: exploring ends when no frontier is left")
    bus = _bus("coordinator", "coordinator", connect, fleet, zenoh_config)
    stored = (w.map_grid, w.source) if floor_map is not None and w.map_grid is not None else None
    source = w.source if w is not None else world
    c = _coordinator_service(
        bus, cfg, robots, store, planner, transits, explore, docks, stored, source
    )
    _stop_on_signals(c.stop)
    try:
        c.run(cfg.coordinator.expected_robots_grace_s, loop)
    finally:
        c.close()
        bus.close()
    if (refusal := c.parts.refusal()) is not None:
        typer.secho(f"error: {refusal}", fg="red", err=True)
        raise typer.Exit(WRONG_MAP_EXIT)


def _coordinator_service(
    bus: Bus,
    cfg: FleetConfig,
    robots: int,
    store: JobStore | None,
    planner: TaskPlanner | None,
    transits: TransitPlanner | None,
    explore: Path | None,
    docks: tuple[Pose, ...],
    stored: tuple[GridMap, Path] | None,
    source: str,
) -> Coordinator:
    """The coordinator on ``bus`` with the parts the options and the config ask for
    (:func:`fleet.coordinator.build.build_coordinator`); exits naming what is wrong."""
    from fleet.coordinator.build import build_coordinator
    from fleet.plausible import Bounds

    try:
        return build_coordinator(
            bus,
            cfg,
            robots,
            store,
            bounds=Bounds.of(cfg),
            planner=planner,
            transits=transits,
            explore=explore,
            docks=docks,
            stored_map=stored,
        )
    except ValueError as e:
        _fail(f"{source}: {e}")


def _coordinator_job(
    robots: int,
    world: str,
    fleet: str,
    config: Path | None,
    state: Path | None,
    deconfliction: str | None,
    explore: Path | None,
    floor_map: Path | None,
):
    """The coordinator's parameters, world (on the stored map of --map; none exploring), docks
    (the world file's, read exploring too when batteries are on), task planner and transit
    planner (none exploring) and job store (none without --state); exits naming what is
    wrong."""
    import sqlite3

    from fleet.config import ConfigError
    from fleet.coordinator.planning import TaskPlanner
    from fleet.coordinator.store import JobStore, StoreError
    from fleet.coordinator.transits import TransitPlanner
    from fleet.world import on_stored_map

    # exploring, the world file is not even opened (but for its docks, with batteries): the
    # robots' maps are all it knows
    cfg, w = _load(config, world if explore is None else None)
    docks = w.docks if w is not None else ()
    if explore is not None and cfg.robot.battery.enabled:
        docks = _load(config, world)[1].docks
    mode = deconfliction or cfg.coordinator.deconfliction
    if explore is not None and mode != "local":
        _fail("--explore plans local transits only; leave out --deconfliction")
    if explore is not None and floor_map is not None:
        _fail("--explore makes a map; --map plans on one: not both")
    if floor_map is not None:
        try:
            w = on_stored_map(w, floor_map)
        except ConfigError as e:
            _fail(str(e))
    planner = transits = None
    try:
        if explore is None:
            planner = TaskPlanner(w, cfg)
            if mode != "local":
                transits = TransitPlanner(w, cfg, mode, planner.transit.clear)
    except ValueError as e:
        _fail(str(e))
    try:
        store = None
        if state is not None:
            name = w.name if w is not None else Path(world).stem
            store = JobStore(state, fleet=fleet, world=name, robots=robots)
    except StoreError as e:
        _fail(str(e))
    except (sqlite3.Error, OSError) as e:
        _fail(f"--state {state}: {e}")
    return cfg, w, docks, planner, transits, store


def register(
    app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app: typer.Typer
) -> None:
    app.command("router")(router)
    app.command("sim")(sim)
    app.command("agent")(agent)
    app.command("coordinator")(coordinator)
