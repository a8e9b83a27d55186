"""The market without a bus: a lost robot's work back on sale, its bids refused, swept tasks
done. The parts are wired as the coordinator wires them, to a publish stand-in that records
what goes out and answers each auction call with the robots' bids through the auctioneer's
handler, as the bus's thread would."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from fleet.config import resolve_world
from fleet.coordinator.auctioneer import Auctioneer, Sale
from fleet.coordinator.awards import Awards
from fleet.coordinator.dispatcher import Dispatcher
from fleet.coordinator.job import ASSIGNED, DONE, LOST, OPEN, REPLACED, Job
from fleet.coordinator.journal import Journal
from fleet.coordinator.market import Market
from fleet.coordinator.planning import TaskPlanner
from fleet.params import CoordinatorParams, load_fleet_config
from fleet.protocol import Award, Bid, FleetEvent, Keys, Message, Plan, RobotStatus, TaskCall
from fleet.world import load_world
from planners.auction import Task
from planners.coverage.params import CoverageParams

KEYS = Keys("test")
PIECES = 4


def _task(i: int) -> Task:
    """The tour's i-th task: PIECES one-metre pieces along x, each task where the last ended."""
    x = PIECES * i + np.arange(PIECES + 1, dtype=float)
    return Task(f"t{i:02d}", np.column_stack([x, np.zeros(PIECES + 1)]), 4.0, 8.0, (1,))


@pytest.fixture(scope="module")
def planner() -> TaskPlanner:
    cfg = load_fleet_config()
    return TaskPlanner(load_world(resolve_world("small"), cfg.robot.radius), cfg)


class Coordinator:
    """The market's parts as the service wires them, with robots that bid ``prices``."""

    def __init__(self, planner: TaskPlanner, robots: list[str]) -> None:
        self.job = Job(CoverageParams())
        self.job.add_tasks(tuple(_task(i) for i in range(6)))
        for rid in robots:
            r = self.job.robot(rid)
            r.ready, r.xy = True, (0.0, 0.0)
        self.sent: list[tuple[str, Message]] = []
        self.sales: list[Sale] = []
        self.bidding: dict[str, float] = {}  # robot -> its price for any lot
        params = CoordinatorParams(bid_timeout_s=0.2)
        self.journal = Journal(self.job, None, KEYS, self.publish)
        self.awards = Awards(self.journal, KEYS, self.publish)
        self.dispatcher = Dispatcher(self.journal, planner, None, params, KEYS, self.publish)
        self.wake = threading.Event()
        self.market = Market(
            self.journal,
            self.awards,
            self.dispatcher,
            threading.RLock(),
            self.wake,
            threading.Event(),
        )
        self.auctioneer = Auctioneer(KEYS, self.publish, params, self._sold)

    def _sold(self, sale: Sale) -> None:
        self.sales.append(sale)
        self.market.sell(sale)

    def publish(self, key: str, msg: Message, _control: bool) -> None:
        self.sent.append((key, msg))
        if isinstance(msg, TaskCall):
            for rid, price in sorted(self.bidding.items()):
                bid = Bid(0.0, msg.round, msg.task, rid, price, price, False)
                self.auctioneer.on_bid(KEYS.bid(msg.task, rid), bid)

    def events(self, kind: str) -> list[tuple[str, str, str]]:
        return [
            (m.robot, m.task, m.detail)
            for _, m in self.sent
            if isinstance(m, FleetEvent) and m.kind == kind
        ]

    def calls(self) -> list[TaskCall]:
        return [m for _, m in self.sent if isinstance(m, TaskCall)]


def test_a_lost_robots_remainder_and_unstarted_tasks_go_back_on_sale_as_regions(
    planner: TaskPlanner,
) -> None:
    c = Coordinator(planner, ["robot-0", "robot-1", "robot-2"])
    job = c.job
    for tid in ("t00", "t01", "t02"):
        job.award(tid, "robot-0", False)
    for tid in ("t03", "t04", "t05"):
        job.award(tid, "robot-1", False)
    c.awards.send()
    job.progress("robot-0", "t00", np.array([1, 1, 0, 0], dtype=np.uint8))
    job.robots["robot-0"].xy = (2.5, 0.05)
    plan = Plan(0.0, 1, "t00", np.zeros((2, 2)), 0)
    c.dispatcher.plans["robot-0"] = plan

    c.market.lose("robot-0", "its liveliness token is gone")

    assert job.robots["robot-0"].liveness == LOST and job.queue("robot-0") == []
    assert job.tasks["t00"].state == REPLACED
    assert [job.tasks[t].state for t in ("t00.1", "t01", "t02")] == [OPEN] * 3
    assert [r.task.id for r in job.queue("robot-1")] == ["t03", "t04", "t05"]
    assert c.events("lost") == [("robot-0", "", "its liveliness token is gone")]
    assert sorted(c.events("reopened")) == [
        ("robot-0", "t00.1", "remainder"),
        ("robot-0", "t01", "unstarted"),
        ("robot-0", "t02", "unstarted"),
    ]
    assert "robot-0" not in c.dispatcher.plans
    emptied = [m for _, m in c.sent if isinstance(m, Award) and m.robot == "robot-0"]
    assert emptied and emptied[-1].tasks == []
    assert c.market.need_auction and c.wake.is_set()

    # the lost robot still bids, and bids lowest: its bids are refused, and its work is sold as
    # one region per robot left in the market, in the order of the tour, to the best of them
    c.bidding = {"robot-0": 1.0, "robot-1": 50.0, "robot-2": 20.0}
    c.market.auction(c.auctioneer)
    regions = [s.lot for s in c.sales]
    assert all(lot.id.startswith("region-") for lot in regions)
    assert sorted(t for lot in regions for t in lot.tasks) == ["t00.1", "t01", "t02"]
    assert len(regions) == 2 and regions[0].tasks[0] == "t00.1"
    assert {s.best.robot for s in c.sales} == {"robot-2"}
    assert c.auctioneer.rejected() == {"not in the market": len(c.calls())}
    assert not job.open_tasks() and not job.queue("robot-0")
    assert sorted(t for _, t, _ in c.events("reassigned")) == ["t00.1", "t01", "t02"]


def test_a_chain_swept_to_its_end_is_done_and_a_task_left_unswept_goes_back_once(
    planner: TaskPlanner,
) -> None:
    c = Coordinator(planner, ["robot-0"])
    job = c.job
    for tid in ("t00", "t01", "t02"):
        job.award(tid, "robot-0", False)
    # one waypoint of transit, then t00 and t01 chained: 8 pieces
    waypoints = np.vstack([[[-1.0, 0.0]], _task(0).path, _task(1).path[1:]])
    plan = Plan(0.0, 4, "t00", waypoints, 1, ["t00", "t01"], np.array([1, 5], dtype=np.int32))
    swept = np.array([1, 1, 1, 1, 1, 0, 1, 1], dtype=np.uint8)

    def status(state: str, plan_id: int = 4) -> RobotStatus:
        return RobotStatus(0.0, state, "t01", 0.5, 9, 10, 0.0, plan_id=plan_id, swept=swept)

    c.market.swept("robot-0", status("driving", plan_id=3), plan)  # another plan's report
    assert not job.tasks["t00"].swept.any()
    c.market.swept("robot-0", status("driving"), plan)
    assert job.tasks["t00"].state == DONE and c.events("done") == [("robot-0", "t00", "")]
    assert job.tasks["t01"].state == ASSIGNED
    assert job.tasks["t01"].swept.tolist() == [True, False, True, True]
    # the plan ended with one piece of t01 unswept: it goes back to the market as t01.1
    c.market.swept("robot-0", status("done"), plan)
    assert job.tasks["t01"].state == REPLACED and job.tasks["t01.1"].state == OPEN
    assert c.events("withdrawn") == [("robot-0", "t01", "pieces given up: once more as t01.1")]
    assert c.market.need_auction
    assert [r.task.id for r in job.queue("robot-0")] == ["t02"]
