"""No sim time passes while the coordinator makes its first plan: the coordinator says so in
its state (phase ``planning``) for as long as it plans, and the simulator holds its clock
while the newest state says so, or until the coordinator's liveliness token goes. A real
simulator and a real coordinator on a real router."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from waits import wait_until

from fleet.bus import Bus
from fleet.config import resolve_world
from fleet.coordinator.planning import TaskPlanner
from fleet.coordinator.service import Coordinator
from fleet.params import load_fleet_config
from fleet.plausible import Bounds
from fleet.protocol import FleetState
from fleet.supervisor.launcher import free_port
from fleet.world import load_world
from sim_server.server import SimServer

pytestmark = pytest.mark.timeout(60)

WORLD = Path(__file__).resolve().parents[2] / "configs" / "worlds" / "small.yaml"
CFG = load_fleet_config(None)


@pytest.fixture
def sim(router_endpoint: str) -> Iterator[tuple[SimServer, str]]:
    """A simulator at real time (no agents) on a real router, and its fleet's name."""
    fleet = f"t{free_port()}"
    bus = Bus("sim", "sim", connect=[router_endpoint], fleet=fleet)
    server = SimServer(bus, load_world(WORLD, CFG.robot.radius), CFG, speed=1.0)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    try:
        yield server, fleet
    finally:
        server.stop.set()
        thread.join(timeout=5.0)
        bus.close()


def _still(server: SimServer, wall_s: float) -> bool:
    """Whether the sim clock stays where it is for ``wall_s`` of wall time."""
    t0 = server.core.t
    time.sleep(wall_s)
    return server.core.t == t0


def test_the_clock_holds_while_the_state_says_planning_and_runs_on_other_news(
    sim: tuple[SimServer, str], router_endpoint: str
) -> None:
    server, fleet = sim
    coord = Bus("coordinator", "coordinator", connect=[router_endpoint], fleet=fleet)
    try:
        assert wait_until(lambda: server.core.t > 0.2), "the clock does not run at all"
        coord.publish(coord.keys.coord_state(), FleetState(0.0, "planning", [], []), control=True)
        assert wait_until(lambda: server.planning)
        assert _still(server, 0.6)
        coord.publish(coord.keys.coord_state(), FleetState(0.0, "gathering", [], []), control=True)
        t0 = server.core.t
        assert wait_until(lambda: server.core.t > t0 + 0.3), "the clock stays held"
        # held again, then the coordinator dies while planning: its token going lets go
        coord.publish(coord.keys.coord_state(), FleetState(0.0, "planning", [], []), control=True)
        assert wait_until(lambda: server.planning)
        assert _still(server, 0.3)
    finally:
        coord.close()
    t0 = server.core.t
    assert wait_until(lambda: server.core.t > t0 + 0.3), "a dead coordinator holds the clock"


def test_a_coordinator_planning_holds_the_simulator_until_its_plan_is_made(
    sim: tuple[SimServer, str], router_endpoint: str
) -> None:
    server, fleet = sim
    planner = TaskPlanner(load_world(resolve_world("small"), CFG.robot.radius), CFG)
    plan, release = planner.tasks, threading.Event()

    def slow_plan():  # the planner at work until the test has seen the clock held
        assert release.wait(30.0)
        return plan()

    planner.tasks = slow_plan  # type: ignore[method-assign]
    bus = Bus("coordinator", "coordinator", connect=[router_endpoint], fleet=fleet)
    coord = Coordinator(bus, planner, 1, CFG.coordinator, None, bounds=Bounds.of(CFG))
    thread = threading.Thread(target=coord.run, args=(1.0,), daemon=True)
    try:
        assert wait_until(lambda: server.core.t > 0.2), "the clock does not run at all"
        thread.start()
        assert wait_until(lambda: server.planning), "the simulator never heard it planning"
        # the state goes out again while planning: one that came before the simulator's
        # subscription, or was lost, holds the clock all the same
        assert _still(server, 1.2)
        release.set()
        assert wait_until(lambda: coord.job.tasks, timeout=20.0), "no plan made"
        t0 = server.core.t
        assert wait_until(lambda: server.core.t > t0 + 0.3), "the clock stays held after the plan"
        assert not server.planning
    finally:
        release.set()
        coord.stop.set()
        thread.join(timeout=10.0)
        coord.close()
        bus.close()
