"""Robots that go to charge, without a bus: one below the threshold is sent to a dock and its
work goes back on sale, a dock is never held by two robots (the second waits by it and goes on
once it is free), a robot that declines all open work on its charge goes to charge, and at the
end of the job every robot is sent home. The market and its charging part are wired as the
coordinator wires them, to a publish stand-in that records what goes out and bids for the
robots."""

from __future__ import annotations

import math
import threading
from pathlib import Path

import numpy as np
import pytest
from bus_stand_in import answer
from robots import ROBOT

from fleet.config import resolve_world
from fleet.coordinator.auctioneer import Auctioneer
from fleet.coordinator.awards import Awards
from fleet.coordinator.charging import APPROACH_M, SPOT_FROM_DOCK_M
from fleet.coordinator.charging_part import ChargingPart, charging_early, going_home, homeward
from fleet.coordinator.dispatcher import Dispatcher
from fleet.coordinator.go_home import nearest_first
from fleet.coordinator.job import DONE, EMPTY, OPEN, STRANDED, UNREACHABLE, Job
from fleet.coordinator.journal import Journal
from fleet.coordinator.market import Market
from fleet.coordinator.parts import Parts
from fleet.coordinator.planning import TaskPlanner
from fleet.coordinator.service import _left_out
from fleet.coordinator.store import JobStore
from fleet.coordinator.transits import TransitPlanner
from fleet.params import CoordinatorParams, load_fleet_config
from fleet.protocol import (
    AuctionCall,
    Award,
    AwardAck,
    FleetEvent,
    Keys,
    Message,
    Plan,
    RobotStatus,
)
from fleet.report.summary import job_report
from fleet.report.up_report import left_out_line
from fleet.world import World, load_world
from planners.auction import Task
from planners.battery import BatterySpec, go_home_below, makespan_with_charging
from planners.coverage.params import CoverageParams

KEYS = Keys("test")
SPEC = BatterySpec(enabled=True, capacity_s=100.0, recharge_threshold=0.2, recharge_to=0.9)


@pytest.fixture(scope="module")
def world() -> World:
    return load_world(resolve_world("small"), ROBOT.radius)


@pytest.fixture(scope="module")
def planner(world: World) -> TaskPlanner:
    return TaskPlanner(world, load_fleet_config())


def _task(i: int) -> Task:
    """A lane across the small room at y = 1 + 0.3 i, four pieces."""
    x = np.linspace(1.0, 3.0, 5)
    return Task(f"t{i:02d}", np.column_stack([x, np.full(5, 1.0 + 0.3 * i)]), 1.0, 8.0, (1,))


class Fleet:
    """The charging market's parts; robots bid ``price`` on every lot, ``declined`` or not."""

    def __init__(
        self,
        planner: TaskPlanner,
        world: World,
        robots: list[str],
        transits: TransitPlanner | None = None,
    ) -> None:
        self.job = Job(CoverageParams(), ROBOT, 0.0)
        self.job.add_tasks(tuple(_task(i) for i in range(4)))
        for i, rid in enumerate(robots):
            r = self.job.robot(rid)
            r.ready, r.xy, r.charge = True, (1.0 + 0.6 * i, 2.5), 1.0
        self.sent: list[tuple[str, Message]] = []
        self.declined = False
        params = CoordinatorParams(bid_timeout_s=0.2)
        self.journal = Journal(self.job, None, KEYS, self.publish)
        self.awards = Awards(self.journal, KEYS, self.publish)
        self.dispatcher = Dispatcher(self.journal, planner, transits, params, KEYS, self.publish)
        self.charging = ChargingPart(SPEC, world.docks)
        self.market = Market(
            self.journal,
            self.awards,
            self.dispatcher,
            threading.RLock(),
            threading.Event(),
            threading.Event(),
            Parts([self.charging]),
        )
        self.planner = planner
        self.charging.wire(self)  # type: ignore[arg-type]
        self.docking = self.charging.docking
        self.auctioneer = Auctioneer(KEYS, self.publish, params, self.market.sell)

    def work_over(self) -> bool:
        return self.job.finished

    def check_stalls(self) -> None:
        """The market's stall watch, then the charging part's (as the coordinator's loop)."""
        self.market.check_stalls()
        self.charging.check_stalls()

    def going_home(self) -> list[tuple[str, str, bool]]:
        """The robots to send home now, with why and whether to park (:func:`going_home`)."""
        return going_home(self.job, self.docking.go_home_below, self.work_over())

    def publish(self, key: str, msg: Message, _control: bool) -> None:
        self.sent.append((key, msg))
        if isinstance(msg, Award):
            self.awards.acked(msg.robot, AwardAck(0.0, msg.seq, msg.robot))
        if isinstance(msg, AuctionCall):
            for rid in self.job.market():
                self.auctioneer.on_bid(KEYS.bids(rid), answer(msg, rid, 10.0, self.declined))

    def events(self) -> list[tuple[str, str, str]]:
        return [(m.kind, m.robot, m.detail) for _, m in self.sent if isinstance(m, FleetEvent)]

    def plans(self, rid: str) -> list[Plan]:
        return [m for k, m in self.sent if isinstance(m, Plan) and k == KEYS.plan(rid)]

    def status(self, rid: str, charge: float, charging: bool, plan: Plan, done: bool) -> None:
        """``rid`` reports its battery and how far along ``plan`` it is; charging, it stands
        at the plan's end (on the dock)."""
        if charging:
            self.job.robots[rid].xy = tuple(plan.waypoints[-1])
        n = len(plan.waypoints)
        waypoint = n if done else 0
        self.dispatcher.heard(rid, plan.plan_id, waypoint)
        msg = RobotStatus(
            0.0, "done" if done else "driving", plan.task, 1.0, waypoint, n, 0.0,
            plan_id=plan.plan_id, charge=charge, charging=charging,
        )  # fmt: skip
        self.observe(rid, msg)

    def observe(self, rid: str, msg: RobotStatus) -> None:
        """A status heard, as the coordinator takes it: the market's stall watch, then the
        charging part (the robot's battery)."""
        self.market.observe(rid, msg)
        self.charging.observe(rid, msg)


def test_a_robot_below_the_threshold_goes_to_a_dock_and_its_work_is_sold_again(
    planner: TaskPlanner, world: World
) -> None:
    f = Fleet(planner, world, ["robot-0", "robot-1"])
    job = f.job
    job.award("t00", "robot-0", False)
    job.award("t01", "robot-0", False)
    f.awards.send()
    job.progress("robot-0", "t00", np.array([1, 1, 0, 0], dtype=np.uint8))
    job.robots["robot-0"].charge = 0.19
    ((rid, why, parking),) = f.going_home()
    assert rid == "robot-0" and why.startswith("charge 0.190 below 0.") and not parking
    for rid, why, parking in f.going_home():
        f.charging.send_home(rid, why, parking)
    r = job.robots["robot-0"]
    assert r.docking == "docking" and "robot-0" not in job.market()
    # the unswept half of t00 and the unstarted t01 are open, not tried by it
    assert job.tasks["t00.1"].state == OPEN and job.tasks["t01"].state == OPEN
    assert not job.tasks["t00.1"].tried and job.queue("robot-0") == []
    assert f.market.need_auction
    awards = [m for _, m in f.sent if isinstance(m, Award) and m.robot == "robot-0"]
    assert awards[-1].tasks == []
    (plan,) = f.plans("robot-0")
    dock = world.docks[0]
    assert (plan.task, plan.kind) == ("dock-0", "dock")
    assert np.linalg.norm(plan.waypoints[-1] - dock[:2]) < SPEC.dock_tolerance / 2
    # it drives onto the dock straight along the dock's axis: facing it when it arrives
    last = plan.waypoints[-1] - plan.waypoints[-2]
    assert math.atan2(last[1], last[0]) == pytest.approx(dock[2] + math.pi - 2 * math.pi)
    # the others bid on its work; it does not
    f.market.auction(f.auctioneer)
    assert job.tasks["t00.1"].owner == "robot-1" and job.tasks["t01"].owner == "robot-1"


def test_a_dock_holds_one_robot_and_the_next_waits_by_it_until_it_is_free(
    planner: TaskPlanner, world: World
) -> None:
    f = Fleet(planner, world, ["robot-0", "robot-1"])
    for rid in ("robot-0", "robot-1"):
        f.job.robots[rid].charge = 0.15
    for rid, why, parking in f.going_home():
        f.charging.send_home(rid, why, parking)
    (to_dock,), (to_wait,) = f.plans("robot-0"), f.plans("robot-1")
    assert (to_dock.task, to_dock.kind) == ("dock-0", "dock")
    assert (to_wait.task, to_wait.kind) == ("wait-0", "wait")
    dock = np.array(world.docks[0][:2])
    assert np.linalg.norm(to_wait.waypoints[-1] - dock) >= SPOT_FROM_DOCK_M
    f.status("robot-0", 0.15, True, to_dock, done=True)
    f.status("robot-1", 0.14, False, to_wait, done=True)
    assert f.job.robots["robot-0"].docking == "charging"
    assert f.docking.tick(False) == [] and len(f.plans("robot-1")) == 1  # still taken
    f.status("robot-0", 0.95, True, to_dock, done=True)
    f.job.award("t00", "robot-0", False)  # it has work: it drives off the dock to it
    assert f.docking.tick(False) == ["robot-0"]
    assert "robot-0" in f.job.market()
    assert len(f.plans("robot-1")) == 1  # robot-0 still stands on the dock
    r0 = f.job.robots["robot-0"]
    r0.xy, r0.charging = (1.0, 2.5), False  # it drives off
    f.docking.tick(False)
    (_, onto) = f.plans("robot-1")
    assert onto.task == "dock-0" and f.job.robots["robot-1"].docking == "docking"


def test_a_robot_that_stands_still_on_its_dock_trip_is_planned_again_then_sent_to_wait(
    planner: TaskPlanner, world: World
) -> None:
    """robot-0, alone on its way to the one dock, makes no progress for the stall time: its
    trip is planned again from where it stands; standing still once more, it is sent to a
    waiting spot instead, and goes on to the dock only once there. A robot that moves on does
    not stall."""
    f = Fleet(planner, world, ["robot-0", "robot-1"])
    f.market.stall_s = 30.0
    r = f.job.robots["robot-0"]
    r.charge = 0.15
    f.charging.send_home("robot-0", "low", False)
    (first,) = f.plans("robot-0")
    r.xy = (1.3, 2.2)
    f.status("robot-0", 0.15, False, first, done=False)
    f.journal.clock = 29.0
    f.check_stalls()
    assert len(f.plans("robot-0")) == 1
    f.journal.clock = 31.0
    f.check_stalls()
    (_, again) = f.plans("robot-0")
    assert again.task == "dock-0" and again.plan_id != first.plan_id
    assert np.allclose(again.waypoints[0], r.xy) and r.docking == "docking"
    assert np.allclose(again.waypoints[-1], first.waypoints[-1])
    f.status("robot-0", 0.14, False, again, done=False)
    f.journal.clock = 62.0
    f.check_stalls()
    (*_, wait) = f.plans("robot-0")
    assert wait.task == "wait-0" and r.docking == "waiting"
    assert [e[0] for e in f.events()].count("dock") == 3, f.events()
    # the dock is free, but it goes on to it from its waiting spot, not from where it stood
    assert f.docking.tick(False) == [] and f.plans("robot-0")[-1] is wait
    f.status("robot-0", 0.13, False, wait, done=True)
    f.docking.tick(False)
    assert f.plans("robot-0")[-1].task == "dock-0" and r.docking == "docking"


def test_a_robot_goes_to_charge_earlier_by_its_trip_and_the_queue_ahead_at_the_dock(
    planner: TaskPlanner, world: World
) -> None:
    """Alone, robot-2 needs the threshold and its trip; behind two robots on their way to the
    one dock at 0.1 it needs 2 × 0.8 × 25 s of their charging more at the idle drain (0.2 of
    it): 0.08 on a 100 s charge. At a charge between the two it stays at work alone and goes
    behind the queue."""
    f = Fleet(planner, world, ["robot-0", "robot-1", "robot-2"])
    alone = go_home_below(SPEC, f.docking.trip_to(0, f.job.robots["robot-2"].xy), [])
    assert SPEC.recharge_threshold < alone < SPEC.recharge_threshold + 0.2  # the trip
    f.job.robots["robot-2"].charge = alone + 0.04
    assert f.docking.go_home_below("robot-2") == pytest.approx(alone)  # the others far from due
    assert f.going_home() == []
    for rid in ("robot-0", "robot-1"):
        f.job.robots[rid].charge = 0.1
        f.charging.send_home(rid, "low", False)
    assert f.docking.go_home_below("robot-2") == pytest.approx(alone + 0.08, abs=1e-9)
    assert [rid for rid, _, _ in f.going_home()] == ["robot-2"]


def test_a_robot_out_of_charge_by_the_dock_is_a_body_and_the_job_ends_instead_of_hanging(
    planner: TaskPlanner, world: World
) -> None:
    """robot-0 runs out on the line onto the one dock, robot-1 waits by it, robot-2 works:
    robot-0's body is planned round and blocks the dock, so robot-1 goes back to work (with no
    dock, it is not sent to charge again); robot-2's work goes back to the market when it runs
    out; once robot-1 runs out too, no robot is left, the open work is left out and the job is
    finished with every robot counted home."""
    planner = TaskPlanner(world, load_fleet_config())  # its bodies are this test's own
    f = Fleet(planner, world, ["robot-0", "robot-1", "robot-2"])
    job = f.job
    job.award("t00", "robot-2", False)
    f.awards.send()
    for rid in ("robot-0", "robot-1"):
        job.robots[rid].charge = 0.1
        f.charging.send_home(rid, "low", False)
    assert job.robots["robot-1"].docking == "waiting"
    dock = world.docks[0]
    on_the_line = (
        dock[0] + 0.5 * APPROACH_M * math.cos(dock[2]),
        dock[1] + 0.5 * APPROACH_M * math.sin(dock[2]),
    )
    job.robots["robot-0"].xy, job.robots["robot-0"].charge = on_the_line, 0.0
    f.charging.check_flat()
    assert job.robots["robot-0"].docking == EMPTY and "robot-0" in f.market.bodies
    assert not f.docking.usable(0)
    assert f.docking.tick(False) == ["robot-1"]
    assert job.robots["robot-1"].docking == "" and "robot-1" in job.market()
    assert f.going_home() == []
    job.robots["robot-2"].charge = 0.0
    f.charging.check_flat()
    assert job.robots["robot-2"].docking == EMPTY and job.tasks["t00"].state == OPEN
    assert not job.finished
    job.robots["robot-1"].charge = 0.0
    f.charging.check_flat()
    assert job.finished and all(r.state == STRANDED for r in job.tasks.values())
    assert [r.task.id for r in job.left_out()] == ["t00", "t01", "t02", "t03"]
    assert [e for e in f.events() if e[0] == "stranded"], f.events()
    assert f.docking.home()


def test_work_stranded_by_robots_out_of_charge_is_not_called_tried_by_every_robot(
    tmp_path: Path,
) -> None:
    """The open work a job leaves when no robot can work any more is ``stranded``, and the end
    message, report.json's ``left_out`` and the CLI's end text say so, not that every robot
    tried it; a task every robot tried keeps its wording."""
    job = Job(CoverageParams(), ROBOT, 0.0)
    job.add_tasks((_task(0), _task(1)))
    job.tasks["t01"].tried = frozenset({"robot-0", "robot-1"})
    job.tasks["t01"].state = UNREACHABLE
    assert job.strand() == ["t00"] and job.finished and len(job.left_out()) == 2
    message = _left_out(job.tasks["t00"])
    assert "stranded: no robot left with charge" in message and "tried" not in message
    assert "tried by robot-0, robot-1" in _left_out(job.tasks["t01"])
    store = JobStore(tmp_path / "coordinator.sqlite")
    store.save_tasks(list(job.tasks.values()))
    store.close()
    stranded, unreachable = job_report(tmp_path / "coordinator.sqlite")["left_out"]
    assert stranded["state"] == "stranded" and unreachable["state"] == UNREACHABLE
    assert left_out_line(stranded).endswith("(stranded: no robot left with charge)")
    assert left_out_line(unreachable).endswith("(tried by robot-0, robot-1)")
    # a robot back in the market takes stranded work up again
    job.robots["robot-0"] = job.robot("robot-0")
    job.robots["robot-0"].ready, job.robots["robot-0"].xy = True, (1.0, 2.5)
    assert job.reopen() == ["t00"]


@pytest.mark.parametrize("declined", [False, True])
def test_the_first_allocation_estimates_the_makespan_with_the_charges_in_it(
    planner: TaskPlanner, world: World, declined: bool
) -> None:
    """Two robots at 0.25 of a 100 s charge, two regions of about 16 s: each must charge
    after 5 s of work, one after the other at the one dock. The estimate counts that, whether
    the auction sold the regions or every robot declined them on its charge."""
    f = Fleet(planner, world, ["robot-0", "robot-1"])
    for rid in ("robot-0", "robot-1"):
        f.job.robots[rid].charge = 0.25
    f.declined = declined
    f.market.auction(f.auctioneer)
    regions = sorted(f.charging.first_regions, key=lambda r: -r[0])
    work, trips = [w for w, _ in regions], [t for _, t in regions]
    assert len(work) == 2 and all(w > 10.0 for w in work)
    assert all(t > 0.5 for t in trips)  # the small room's dock is a few metres from the lanes
    want = makespan_with_charging(SPEC, work, [0.25, 0.25], 1, trips)
    no_trips = makespan_with_charging(SPEC, work, [0.25, 0.25], 1)
    assert want > no_trips > max(work) + 2 * 0.65 * SPEC.capacity_s / SPEC.charge_rate
    (detail,) = [d for kind, _, d in f.events() if kind == "estimated"]
    assert detail == f"makespan {want:.1f} s"


def test_a_robot_that_declines_every_open_task_on_its_charge_goes_to_charge(
    planner: TaskPlanner, world: World
) -> None:
    f = Fleet(planner, world, ["robot-0"])
    f.job.robots["robot-0"].charge = 0.5
    f.declined = True
    f.market.auction(f.auctioneer)
    assert all(rec.state == OPEN for rec in f.job.tasks.values())
    assert f.job.robots["robot-0"].docking == "docking"


def test_regions_are_sold_only_when_each_robot_can_do_one_on_its_charge(
    planner: TaskPlanner, world: World
) -> None:
    f = Fleet(planner, world, ["robot-0", "robot-1"])
    assert len(f.market._regions()[1]()) == 2  # 16 s each against 100 s of charge
    f.job.robots["robot-1"].charge = 0.1
    assert f.market._regions()[1]() == ()


def test_at_the_end_of_the_job_every_robot_goes_home(planner: TaskPlanner, world: World) -> None:
    f = Fleet(planner, world, ["robot-0", "robot-1"])
    for rec in f.job.tasks.values():
        rec.state = DONE
    assert [(rid, parking) for rid, _, parking in f.going_home()] == [
        ("robot-0", True),
        ("robot-1", True),
    ]
    for rid, why, parking in f.going_home():
        f.charging.send_home(rid, why, parking)
    assert not f.docking.home()
    f.status("robot-0", 0.5, True, f.plans("robot-0")[-1], done=True)
    f.status("robot-1", 0.5, False, f.plans("robot-1")[-1], done=True)
    assert f.docking.home() and f.going_home() == []
    # charged at the end of the job, a robot stays on its dock
    f.status("robot-0", 0.95, True, f.plans("robot-0")[-1], done=True)
    assert f.docking.tick(True) == [] and f.job.robots["robot-0"].docking == "charging"


def test_batteries_off_send_no_one_home(planner: TaskPlanner, world: World) -> None:
    f = Fleet(planner, world, ["robot-0"])
    f.job.robots["robot-0"].charge = -1.0  # no battery heard
    assert going_home(f.job, lambda _rid: 0.5, f.job.finished) == []


@pytest.fixture(scope="module")
def corridor() -> World:
    return load_world(resolve_world("corridor"), ROBOT.radius)


def test_at_the_end_of_the_job_each_dock_goes_to_the_robot_nearest_it(corridor: World) -> None:
    """The corridor world, a dock per room: robot-1 stands by the right room's dock, robot-0
    farther off in the same room, robot-2 in the left room. Each dock goes to the robot
    nearest it and the third waits in its room; in id order robot-0 would take the right
    dock and robot-1 cross the corridor to the left one."""
    f = Fleet(TaskPlanner(corridor, load_fleet_config()), corridor, ["robot-0"])
    where = {"robot-0": (5.6, 2.5), "robot-1": (7.0, 0.9), "robot-2": (1.2, 2.2)}
    for rid, xy in where.items():
        r = f.job.robot(rid)
        r.ready, r.xy, r.charge = True, xy, 0.5
    for rec in f.job.tasks.values():
        rec.state = DONE
    home = {rid: (why, p) for rid, why, p in f.going_home()}
    for rid in nearest_first(f.docking, list(home)):
        f.charging.send_home(rid, *home[rid])
    tasks = {rid: f.plans(rid)[-1].task for rid in where}
    assert tasks == {"robot-0": "wait-1", "robot-1": "dock-1", "robot-2": "dock-0"}, tasks
    assert all(f.plans(rid)[-1].waypoints[:, 0].min() > 5.0 for rid in ("robot-0", "robot-1"))


def test_a_robot_sent_to_a_dock_by_its_number_goes_there_and_waits_by_it_when_held(
    corridor: World,
) -> None:
    """`fleet dock ROBOT --dock K`: a robot in the right room sent to the left room's dock
    crosses to it, though its charge would have it charge in its own room; a second robot
    sent to the same dock waits by it."""
    f = Fleet(TaskPlanner(corridor, load_fleet_config()), corridor, ["robot-0", "robot-1"])
    f.job.robots["robot-0"].xy, f.job.robots["robot-1"].xy = (7.0, 2.6), (6.5, 2.6)
    f.charging.send_home("robot-0", "sent home by cli", False)
    assert f.plans("robot-0")[-1].task == "dock-1"  # its own room's, by default
    f.charging.send_home("robot-1", "sent home by cli", False, dock=0)
    assert f.plans("robot-1")[-1].task == "dock-0"
    assert f.plans("robot-1")[-1].waypoints[-1][0] < 3.0  # across the corridor
    g = Fleet(TaskPlanner(corridor, load_fleet_config()), corridor, ["robot-0", "robot-1"])
    g.job.robots["robot-0"].xy, g.job.robots["robot-1"].xy = (7.0, 2.6), (6.5, 2.6)
    g.charging.send_home("robot-0", "sent home by cli", False, dock=0)
    g.charging.send_home("robot-1", "sent home by cli", False, dock=0)
    assert g.plans("robot-1")[-1].task == "wait-0"
    assert ("dock", "robot-1", "sent home by cli: to wait by dock 0") in g.events()


def test_trips_to_docks_through_the_corridor_both_ways_are_planned_in_one_round(
    corridor: World,
) -> None:
    """Under ``prioritized`` a trip to a dock is a transit of a round like any other: robot-0
    sent from the left room to the right room's dock, then robot-1 from the right room to the
    left room's, while robot-0 is still on its way. The second round plans both (robot-0's trip
    goes out again under a new plan id), one of them waits for the other to pass, and each
    plan carries its schedule; with local transits neither waits."""
    cfg = load_fleet_config()
    planner = TaskPlanner(corridor, cfg)
    transits = TransitPlanner(corridor, cfg, "prioritized", planner.transit.clear)
    f = Fleet(planner, corridor, ["robot-0", "robot-1"], transits)
    f.job.robots["robot-0"].xy, f.job.robots["robot-1"].xy = (1.2, 1.5), (6.8, 2.6)
    f.charging.send_home("robot-0", "sent home by cli", False, dock=1)
    first = f.plans("robot-0")[-1]
    f.charging.send_home("robot-1", "sent home by cli", False, dock=0)
    again, other = f.plans("robot-0")[-1], f.plans("robot-1")[-1]
    assert (again.task, other.task) == ("dock-1", "dock-0")
    assert again.plan_id > first.plan_id and f.docking.trips["robot-0"].plan is again
    waits = {(p.task, peer) for p in (again, other) for peer in p.wait_for}
    assert waits in ({("dock-1", "robot-1")}, {("dock-0", "robot-0")}), waits
    assert {"robot-0", "robot-1"} <= set(f.dispatcher.schedules)
    # from where it stands and into the point in front of the dock, not via their cells' points
    assert np.allclose(again.waypoints[0], (1.2, 1.5))
    assert np.allclose(again.waypoints[-2], (corridor.docks[1][0] - APPROACH_M, 1.0))
    legs = np.diff(again.waypoints, axis=0)
    headings = np.arctan2(legs[:, 1], legs[:, 0])
    turns = np.abs(np.remainder(np.diff(headings) + np.pi, 2 * np.pi) - np.pi)
    assert turns[-1] < 0.6, again.waypoints  # no turn in place before driving onto the dock
    for plan in (again, other):  # through the corridor (faces at y 1.2 and 1.7, x 3 to 5)
        inside = plan.waypoints[(plan.waypoints[:, 0] > 3.2) & (plan.waypoints[:, 0] < 4.8)]
        assert len(inside) and np.all(np.abs(inside[:, 1] - 1.45) < 0.08), plan.waypoints
    g = Fleet(planner, corridor, ["robot-0", "robot-1"])
    g.job.robots["robot-0"].xy, g.job.robots["robot-1"].xy = (1.2, 1.5), (6.8, 2.6)
    g.charging.send_home("robot-0", "sent home by cli", False, dock=1)
    g.charging.send_home("robot-1", "sent home by cli", False, dock=0)
    assert not any(g.plans(rid)[-1].wait_for for rid in ("robot-0", "robot-1"))


def test_a_robot_at_work_passing_over_a_dock_does_not_hold_it(corridor: World) -> None:
    """A robot sweeping a lane over a dock's pose leaves it free for a robot going to charge;
    one standing there without work, or charging, holds it."""
    f = Fleet(TaskPlanner(corridor, load_fleet_config()), corridor, ["robot-0", "robot-1"])
    f.market.auction(f.auctioneer)
    worker, other = f.job.robots["robot-0"], f.job.robots["robot-1"]
    assert f.job.queue("robot-0")
    worker.xy, other.xy, other.charge = (7.5, 1.05), (7.0, 2.6), 0.1
    assert f.docking.holder(1) is None
    f.charging.send_home("robot-1", "charge low", False)
    assert f.plans("robot-1")[-1].task == "dock-1"
    g = Fleet(TaskPlanner(corridor, load_fleet_config()), corridor, ["robot-0"])
    g.job.robots["robot-0"].xy = (7.5, 1.05)
    assert g.job.queue("robot-0") == [] and g.docking.holder(1) == "robot-0"


def test_a_robot_passing_over_another_dock_on_its_way_is_not_charging_on_its_own(
    corridor: World,
) -> None:
    """The simulator charges a robot on any dock it stands on; one on its way to the right
    room's dock that passes over the left one is still on its way, not charging on its dock."""
    f = Fleet(TaskPlanner(corridor, load_fleet_config()), corridor, ["robot-0", "robot-1"])
    f.job.robots["robot-0"].xy = (1.0, 0.6)
    f.charging.send_home("robot-0", "charge low", False)  # it takes the left dock
    f.job.robots["robot-1"].xy = (1.2, 2.2)
    f.charging.send_home("robot-1", "the job is done", True)  # to the free dock
    (trip,) = f.plans("robot-1")
    assert trip.task == "dock-1"
    f.job.robots["robot-1"].xy = (0.5, 1.5)  # over the left dock
    status = RobotStatus(
        0.0, "driving", trip.task, 0.5, 1, 4, 0.0, plan_id=trip.plan_id, charge=0.3, charging=True
    )
    f.observe("robot-1", status)
    assert f.job.robots["robot-1"].docking == "docking"
    assert not [e for e in f.events() if e[0] == "charging" and e[1] == "robot-1"]


def test_of_two_robots_falling_due_together_the_first_is_sent_to_the_free_dock_early(
    planner: TaskPlanner, world: World
) -> None:
    """Two robots at work that both need a charge for the work they hold, both a few seconds
    from their go-home points: the one due first goes to the free dock now, so it is charged
    before the other falls due. Not while another robot is bound for the dock, and not for
    robots whose charge covers what they hold and their share of the work left (robot-2, idle
    on 0.5 or more, never)."""
    f = Fleet(planner, world, ["robot-0", "robot-1", "robot-2"])
    spec = BatterySpec(enabled=True, capacity_s=40.0)
    f.docking.spec = f.charging.battery = spec
    for i, rid in enumerate(("robot-0", "robot-1")):
        for tid in (f"t{2 * i:02d}", f"t{2 * i + 1:02d}"):
            f.job.award(tid, rid, False)
    for rid, ahead in (("robot-0", 0.06), ("robot-1", 0.05), ("robot-2", 0.5)):
        found = f.docking.dock_user(rid)
        assert found is not None
        f.job.robots[rid].charge = 0.2 + found[1].trip_s / spec.capacity_s + ahead
    assert f.going_home() == []  # none at its go-home point
    assert f.docking.send("robot-2", "sent by hand", False)
    assert charging_early(f.job, f.docking, f.job.finished) == []  # the dock is taken
    f.docking._drop("robot-2")
    ((rid, why),) = charging_early(f.job, f.docking, f.job.finished)
    assert rid == "robot-1" and "charging early" in why
    for tid in ("t02", "t03"):
        f.job.tasks[tid].swept[:] = True  # robot-1 has swept all it holds: its charge covers it
    assert charging_early(f.job, f.docking, f.job.finished) == []
    f.job.add_tasks(tuple(_task(i) for i in range(4, 8)))  # unless much work is still on sale
    assert [rid for rid, _ in charging_early(f.job, f.docking, f.job.finished)] == ["robot-1"]


def test_of_two_robots_falling_due_in_one_tick_by_one_dock_the_second_waits_on_a_reserve_for_it(
    corridor: World,
) -> None:
    """The corridor world at capacity 120 s: robot-1 and robot-2, both in the right room, fall
    due in the same tick, the right room's dock near both. One takes it; the other waits by it
    (behind a charge of about 21 s at the idle drain) rather than cross the corridor to the left
    one (a trip of some 25 s at the sweeping drain), and the charge each is sent on covers the
    reserve for where it is actually sent: its trip there and the robot ahead of it."""
    f = Fleet(TaskPlanner(corridor, load_fleet_config()), corridor, ["robot-0"])
    spec = BatterySpec(enabled=True, capacity_s=120.0)
    f.docking.spec = f.charging.battery = spec
    where = {"robot-0": (1.2, 2.2), "robot-1": (6.2, 0.6), "robot-2": (6.0, 2.5)}
    for rid, xy in where.items():
        r = f.job.robot(rid)
        r.ready, r.xy, r.charge = True, xy, 0.9
    for _ in range(3):  # each a step below its go-home point, counting the other's charge
        for rid in ("robot-1", "robot-2"):
            f.job.robots[rid].charge = f.docking.go_home_below(rid) - 0.001
    home = homeward(f.job, f.docking, f.job.finished)
    assert sorted(rid for rid, _, _ in home) == ["robot-1", "robot-2"]
    ahead: dict[int, list[float]] = {}
    for rid, why, parking in home:
        f.charging.send_home(rid, why, parking)
        trip = f.plans(rid)[-1]
        k = int(trip.task.split("-")[1])
        r = f.job.robots[rid]
        reserve = go_home_below(spec, f.docking.trip_to(k, r.xy), ahead.get(k, []))
        assert r.charge > reserve - 0.002, (rid, trip.task, r.charge, reserve)  # fell due by 0.001
        ahead.setdefault(k, []).append(r.charge)
    tasks = sorted(f.plans(rid)[-1].task for rid in ("robot-1", "robot-2"))
    assert tasks == ["dock-1", "wait-1"], tasks


def test_a_charged_robot_without_work_on_the_dock_is_sent_off_it_for_a_waiting_robot(
    corridor: World,
) -> None:
    """robot-2 has charged on the right room's dock and won no work: it holds the dock, so
    robot-0, sent to charge, waits by it; but it would stand there until it won work (and it
    does not step aside: robot-0's path stops short of it). So once robot-0 stands at its
    waiting spot, robot-2 is sent to another spot and robot-0 onto the dock; robot-2 is back in
    the market once at its spot. Below ``recharge_to`` it stays and charges."""
    f = Fleet(TaskPlanner(corridor, load_fleet_config()), corridor, ["robot-0"])
    spec = BatterySpec(enabled=True, capacity_s=120.0)
    f.docking.spec = f.charging.battery = spec
    on_dock = (corridor.docks[1][0] - 0.04, corridor.docks[1][1])
    for rid, xy, charge in (("robot-0", (6.2, 0.6), 0.3), ("robot-2", on_dock, 0.92)):
        r = f.job.robot(rid)
        r.ready, r.xy, r.charge, r.charging = True, xy, charge, rid == "robot-2"
    assert f.docking.holder(1) == "robot-2"
    f.charging.send_home("robot-0", "charge low", False)
    (wait,) = f.plans("robot-0")
    assert wait.task == "wait-1"
    f.docking.tick(False)
    assert f.plans("robot-0") == [wait] and not f.plans("robot-2")  # not at its spot yet
    f.status("robot-0", 0.28, False, wait, done=True)
    f.job.robots["robot-2"].charge = 0.85
    f.docking.tick(False)
    assert f.plans("robot-0") == [wait] and not f.plans("robot-2")
    f.job.robots["robot-2"].charge = 0.92
    assert f.docking.tick(False) == []
    (off,) = f.plans("robot-2")
    assert off.task == "wait-1" and "robot-2" not in f.job.market()
    assert not np.allclose(off.waypoints[-1], wait.waypoints[-1])
    assert f.plans("robot-0")[-1].task == "dock-1"
    f.status("robot-2", 0.92, False, off, done=True)
    assert f.docking.tick(False) == ["robot-2"] and "robot-2" in f.job.market()


def test_a_robot_that_stops_charging_off_its_dock_docks_again(
    planner: TaskPlanner, world: World
) -> None:
    """robot-0 charged on arriving at the dock, then stopped charging below ``recharge_to``
    (it stood just off the dock's tolerance): it is docking again and, after the grace,
    drives onto the dock again instead of standing there until it runs out."""
    f = Fleet(planner, world, ["robot-0"])
    f.job.robots["robot-0"].charge = 0.15
    f.charging.send_home("robot-0", "low", False)
    (trip,) = f.plans("robot-0")
    f.status("robot-0", 0.15, True, trip, done=True)
    assert f.job.robots["robot-0"].docking == "charging"
    f.status("robot-0", 0.3, False, trip, done=True)
    assert f.job.robots["robot-0"].docking == "docking"
    f.docking.tick(False)
    f.journal.clock = 10.0
    f.docking.tick(False)
    (_, again) = f.plans("robot-0")
    assert again.task == "dock-0" and again.plan_id != trip.plan_id
