"""The wiring of the coordinator's parts, not their rules (each part's rules are tested with
its parts set up by hand): the factory gives the coordinator the parts the configuration and
the options ask for, alone and together, each wired to that coordinator and serving its keys;
and a coordinator exploring with batteries, on a real router, hears a robot's battery in its
status, sends the robot to a dock on the merged map once it falls due, and watches that trip
for a stall on ``coordinator.stall_s``."""

from __future__ import annotations

import dataclasses
import math
import threading
from collections.abc import Callable
from pathlib import Path

import pytest
from bus_stand_in import NoBus
from test_coordinator_exploring import patches, room
from test_explore_part import robot_and_clock
from waits import wait_until

from fleet.bus import Bus
from fleet.config import resolve_world
from fleet.coordinator.build import build_coordinator
from fleet.coordinator.charging_part import ChargingPart
from fleet.coordinator.explore_part import ExplorePart
from fleet.coordinator.map_watch import MapWatch
from fleet.coordinator.planning import TaskPlanner
from fleet.params import FleetConfig, load_fleet_config
from fleet.plausible import Bounds
from fleet.protocol import (
    Docks,
    FleetEvent,
    FleetState,
    Message,
    Plan,
    Request,
    RobotStatus,
)
from fleet.world import World, load_world

pytestmark = pytest.mark.timeout(60)

CFG = load_fleet_config()
# a dock in the room of test_coordinator_exploring.room (its floor 0.45-2.75 m each way),
# facing into it
DOCK = (1.0, 0.8, math.pi / 2)


class RecordingBus(NoBus):
    """A bus stand-in that records the keys subscribed to and served, and what goes out."""

    def __init__(self) -> None:
        super().__init__()
        self.subscribed: list[str] = []
        self.served: list[str] = []
        self.sent: list[tuple[str, Message]] = []

    def subscribe(self, key: str, *_args: object) -> None:
        self.subscribed.append(key)

    def serve(self, key: str, *_args: object) -> None:
        self.served.append(key)

    def publish(self, key: str, msg: Message, control: bool = False) -> None:
        self.sent.append((key, msg))

    def dropped(self) -> tuple[int, int]:
        return 0, 0


def _with_battery(cfg: FleetConfig, **battery: float) -> FleetConfig:
    spec = dataclasses.replace(cfg.robot.battery, enabled=True, **battery)
    return dataclasses.replace(cfg, robot=dataclasses.replace(cfg.robot, battery=spec))


@pytest.fixture(scope="module")
def world() -> World:
    return load_world(resolve_world("small"), CFG.robot.radius)


@pytest.fixture(scope="module")
def planner(world: World) -> TaskPlanner:
    return TaskPlanner(world, CFG)


CASES = {
    "cleaning": (False, False, False, []),
    "batteries": (True, False, False, [ChargingPart]),
    "exploring": (False, True, False, [ExplorePart]),
    "exploring with batteries": (True, True, False, [ExplorePart, ChargingPart]),
    "on a stored map": (False, False, True, [MapWatch]),
    "on a stored map with batteries": (True, False, True, [ChargingPart, MapWatch]),
}


@pytest.mark.parametrize("case", list(CASES))
def test_the_factory_gives_the_coordinator_the_parts_asked_for_each_wired_to_it(
    case: str, world: World, planner: TaskPlanner, tmp_path: Path
) -> None:
    battery, explore, stored, kinds = CASES[case]
    cfg = _with_battery(CFG) if battery else CFG
    bus = RecordingBus()
    c = build_coordinator(
        bus,  # type: ignore[arg-type]
        cfg,
        2,
        None,
        bounds=Bounds.of(cfg),
        planner=planner,
        explore=tmp_path if explore else None,
        docks=world.docks,
        stored_map=(world.grid(0.05), world.source) if stored else None,
    )
    assert [type(p) for p in c.parts.all] == kinds
    keys = bus.keys
    assert (keys.docks() in bus.served) == battery and (keys.ops("dock") in bus.served) == battery
    assert (keys.floor_map() in bus.served) == (not explore)
    assert (keys.explored_map() in bus.served) == explore
    assert (keys.all_robots("map") in bus.subscribed) == (explore or stored)
    assert c.parts.working == ("exploring" if explore else "cleaning")
    charging = c.parts.of(ChargingPart)
    if charging is not None:
        assert charging.host is c and charging.docking.docks == world.docks
        assert charging.docking.planner is c.planner and charging.market is c.market
    exploring = c.parts.of(ExplorePart)
    if exploring is not None:
        assert exploring.host is c and exploring.explorer.planner is c.planner
        assert exploring.explorer.out_dir == tmp_path
    else:
        assert c.planner is planner
    watch = c.parts.of(MapWatch)
    if watch is not None:
        assert watch.coordinator is c and watch.robots == 2
        assert watch.changes.coordinator is c


def test_the_factory_refuses_batteries_without_a_dock(planner: TaskPlanner) -> None:
    with pytest.raises(ValueError, match="no dock"):
        build_coordinator(
            RecordingBus(),  # type: ignore[arg-type]
            _with_battery(CFG),
            1,
            None,
            bounds=Bounds.of(CFG),
            planner=planner,
        )


def test_exploring_the_work_is_over_when_no_frontier_is_left_not_when_no_task_is_open(
    tmp_path: Path,
) -> None:
    """With batteries, a robot is sent home to park once the job's work is over: exploring,
    that is when the explorer finds no frontier left, not each time the frontiers sold so far
    are all done (then the charging part would park the fleet between two updates)."""
    cfg = _with_battery(CFG)
    c = build_coordinator(
        RecordingBus(),  # type: ignore[arg-type]
        cfg,
        1,
        None,
        bounds=Bounds.of(cfg),
        explore=tmp_path,
        docks=(DOCK,),
    )
    exploring = c.parts.of(ExplorePart)
    assert exploring is not None

    def update(at: float, door: bool, north: bool = False) -> None:
        """An update of the explorer at sim time ``at`` on robot-0's map of the room (with an
        opening in its east wall, ``door``, or in its north wall, ``north``)."""
        cells = room(door)
        if north:
            cells[55, 22:42] = 0
        c.journal.heard(at)
        with c.lock:
            exploring.explorer.maps.hear("robot-0", patches(cells, round(at)))
            exploring.tick()
        exploring.unlocked()

    with c.lock:
        robot = c.job.robot("robot-0")
        robot.ready, robot.xy, robot.charge = True, (1.6, 1.6), 0.9
    update(1.0, door=True)  # the merged map is the floor planned on; its door is a frontier
    with c.lock:
        assert c.job.tasks
        for tid in list(c.job.tasks):
            c.job.award(tid, "robot-0", False)
            c.job.finish("robot-0", tid)
        assert c.job.finished and not c.work_over()
        c.parts.tick()
        assert robot.docking == ""  # not parked between two updates
    update(5.0, door=False)  # the door is a wall: no frontier left
    with c.lock:
        assert c.work_over() and not c._finished()
        c.parts.tick()
        assert robot.docking == "docking"  # the work is over: home, to park
        assert not c._finished()  # until it is there
    update(9.0, door=False, north=True)  # over for good: no update after it finds work
    with c.lock:
        assert c.work_over() and not c.job.open_tasks()


def _status(agent: Bus, plans: list[Plan], charge: float) -> Callable[[float], None]:
    """robot-0's status at sim time ``t``, reporting ``charge``: it drives the last plan it
    was sent (``plans``) and is still at its first waypoint (it never moves)."""

    def send(t: float) -> None:
        plan = plans[-1] if plans else None
        status = RobotStatus(
            t, "driving" if plan else "waiting", plan.task if plan else "", 0.0, 0,
            len(plan.waypoints) if plan else 0, 0.0, plan_id=plan.plan_id if plan else -1,
            charge=charge,
        )  # fmt: skip
        agent.publish(agent.keys.robot("robot-0", "status"), status, control=True)

    return send


def test_exploring_with_batteries_a_robot_that_falls_due_is_sent_to_a_dock_and_its_trip_watched(
    buses: tuple[Bus, Bus, Bus], tmp_path: Path
) -> None:
    """The composed coordinator's loop: the robot's map reaches the explorer (the exploring
    part's subscription), an update makes the merged map the floor planned on (its unlocked
    hook), the battery in its status reaches the charging part (the status hook), which sends
    it to the dock on that floor (its tick) and serves the docks, and, the robot standing
    still on its trip for ``coordinator.stall_s``, plans the trip again (the stall hook)."""
    cbus, sim, agent = buses
    cfg = _with_battery(CFG)
    cfg = dataclasses.replace(cfg, coordinator=dataclasses.replace(cfg.coordinator, stall_s=3.0))
    c = build_coordinator(
        cbus, cfg, 1, None, bounds=Bounds.of(cfg), explore=tmp_path, docks=(DOCK,)
    )
    plans: list[Plan] = []
    events: list[FleetEvent] = []
    agent.subscribe(agent.keys.plan("robot-0"), Plan, lambda _key, plan: plans.append(plan))
    agent.subscribe(agent.keys.events(), FleetEvent, lambda _key, e: events.append(e))
    states: list[FleetState] = []
    agent.subscribe(agent.keys.coord_state(), FleetState, lambda _key, s: states.append(s))
    stop = threading.Event()
    low = cfg.robot.battery.recharge_threshold / 2
    also = _status(agent, plans, low)
    feeder = threading.Thread(target=robot_and_clock, args=(sim, agent, stop, also), daemon=True)
    runner = threading.Thread(target=c.run, args=(0.5,), daemon=True)

    def trips() -> list[Plan]:
        return [p for p in plans if p.kind == "dock"]

    try:
        assert wait_until(lambda: "robot-0" in c.job.robots), "robot-0's token not heard"
        runner.start()
        # the coordinator's state heard, the events subscription declared with it is in
        # effect too: the first dock event, sent once the robot reports its charge, is not lost
        assert wait_until(lambda: states, timeout=10), "no coordinator state heard"
        feeder.start()
        assert wait_until(lambda: trips(), timeout=20), (plans, events)
        docks = agent.request(agent.keys.docks(), Request("robot-0"), Docks, 2.0)
        assert docks.poses.tolist() == [list(DOCK)]
        assert wait_until(lambda: len(trips()) >= 2, timeout=20), (plans, events)
    finally:
        c.stop.set()
        stop.set()
        runner.join(10)
        feeder.join(5)
        c.close()
    first, again = trips()[:2]
    assert first.task == again.task == "dock-0" and again.plan_id > first.plan_id
    told = [e.detail for e in events if e.kind == "dock" and e.robot == "robot-0"]
    # sent for its low charge; when the explorer has open work by then (under load), for the
    # work that charge cannot do
    assert told[0].startswith(
        (f"charge {low:.3f} below ", f"can do none of the open work on {low:.2f}")
    ), told
    assert "no progress on its trip" in told[1] and "planned again" in told[1], told
    assert (tmp_path / "map.yaml").exists()  # the explorer wrote the merged map
