"""The market without a bus: a lost robot's work back on sale, its bids refused, swept tasks
done. The parts are wired as the coordinator wires them, to a publish stand-in that records
what goes out and answers each auction call with the robots' bids through the auctioneer's
handler, as the bus's thread would."""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from bus_stand_in import answer
from robots import ROBOT

from fleet.bench.recovery import to_reassign
from fleet.config import resolve_world
from fleet.coordinator.auctioneer import Auctioneer, Sale
from fleet.coordinator.awards import Awards
from fleet.coordinator.dispatcher import PLAN_RESEND_S, Dispatcher
from fleet.coordinator.job import ASSIGNED, DONE, LOST, OPEN, REPLACED, Job
from fleet.coordinator.journal import Journal
from fleet.coordinator.looping import next_job
from fleet.coordinator.market import Market
from fleet.coordinator.planning import TaskPlanner
from fleet.coordinator.store import JobStore
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
from fleet.world import load_world
from planners.auction import Task
from planners.coverage.params import CoverageParams
from planners.polyline import densify

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
        self.job = Job(CoverageParams(), ROBOT, 0.0)
        self.job.add_tasks(tuple(_task(i) for i in range(6)))
        for i, rid in enumerate(robots):
            r = self.job.robot(rid)
            r.ready, r.xy = True, (0.0, 2.0 * i)  # 2 m apart: no peer holds another up
        self.sent: list[tuple[str, Message]] = []
        self.sales: list[Sale] = []
        self.bidding: dict[str, float] = {}  # robot -> its price for any lot
        # robots acknowledge each award at once, or this many wall seconds after it is sent
        self.ack_after_s = 0.0
        # at each auction call, the robots that had not acknowledged their last award
        self.unacked_at_call: list[list[str]] = []
        # called with each auction call before the robots bid on it
        self.on_call: Callable[[AuctionCall], None] = lambda _call: None
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

    def _ack(self, award: Award) -> None:
        with self.market.lock:
            self.awards.acked(award.robot, AwardAck(0.0, award.seq, award.robot))

    def publish(self, key: str, msg: Message, _control: bool) -> None:
        self.sent.append((key, msg))
        if isinstance(msg, Award):
            if self.ack_after_s > 0:
                threading.Timer(self.ack_after_s, self._ack, (msg,)).start()
            else:
                self._ack(msg)
        if isinstance(msg, AuctionCall):
            self.on_call(msg)
            with self.market.lock:
                robots = self.job.robots.values()
                self.unacked_at_call.append(
                    sorted(r.id for r in robots if r.acked_seq < r.award_seq)
                )
            for rid, price in sorted(self.bidding.items()):
                self.auctioneer.on_bid(KEYS.bids(rid), answer(msg, rid, price))

    def events(self, kind: str) -> list[tuple[str, str, str]]:
        return [
            (m.robot, m.task, m.detail)
            for _, m in self.sent
            if isinstance(m, FleetEvent) and m.kind == kind
        ]

    def calls(self) -> list[AuctionCall]:
        return [m for _, m in self.sent if isinstance(m, AuctionCall)]


def test_a_round_is_called_only_once_the_last_winner_has_acknowledged_its_award(
    planner: TaskPlanner,
) -> None:
    """Sequential auctions price each round from what the robots have won: a robot that bids
    before its award reaches it bids as if it held nothing and wins again. Here each robot
    acknowledges 50 ms after its award is sent, as a loaded one does."""
    c = Coordinator(planner, ["robot-0", "robot-1", "robot-2"])
    c.bidding = {"robot-0": 1.0, "robot-1": 2.0, "robot-2": 3.0}
    c.ack_after_s = 0.05
    c.market.auction(c.auctioneer)
    assert len(c.sales) == 3 and len(c.unacked_at_call) == 3
    assert all(unacked == [] for unacked in c.unacked_at_call), c.unacked_at_call


def test_a_lot_whose_task_went_while_its_round_was_called_is_not_sold(
    planner: TaskPlanner,
) -> None:
    """A robot lost while a round waits for bids can take its lots off the market (a body in
    the way replaces the tasks near it): the round is called again with what is on sale, and
    the task that went is never awarded (it was: ValueError, and the coordinator died)."""
    c = Coordinator(planner, ["robot-0", "robot-1"])
    c.bidding = {"robot-0": 1.0, "robot-1": 2.0}

    def replace_t00(call: AuctionCall) -> None:
        if c.job.tasks["t00"].state == OPEN:
            c.job.tasks["t00"].state = REPLACED

    c.on_call = replace_t00
    c.market.auction(c.auctioneer)
    sold = [t for s in c.sales for t in s.lot.tasks]
    assert "t00" not in sold and sorted(sold) == ["t01", "t02", "t03", "t04", "t05"]
    assert c.job.tasks["t00"].state == REPLACED and not c.job.open_tasks()


def test_a_plan_its_robot_does_not_drive_is_sent_again(planner: TaskPlanner) -> None:
    """A plan lost, or dropped by an agent that did not hold its task yet when it came, left
    the robot idle with its work assigned for good (a chaos run hung so): while the robot's
    statuses show another plan, its plan goes out again every PLAN_RESEND_S."""
    c = Coordinator(planner, ["robot-0"])
    c.job.robots["robot-0"].xy = (0.5, 0.5)
    c.job.award("t00", "robot-0", False)
    c.awards.send()
    c.dispatcher.dispatch()
    plans = [m for _, m in c.sent if isinstance(m, Plan)]
    assert len(plans) == 1
    sent = c.dispatcher.sent_wall["robot-0"]
    c.dispatcher.heard("robot-0", plans[0].plan_id - 1, 3)  # it drives an older plan
    c.dispatcher.resend_unheard(sent + 0.5)  # not yet: it may not have said so yet
    c.dispatcher.resend_unheard(sent + PLAN_RESEND_S + 0.1)
    c.dispatcher.resend_unheard(sent + PLAN_RESEND_S + 0.2)  # once per PLAN_RESEND_S
    again = [m for _, m in c.sent if isinstance(m, Plan)]
    assert len(again) == 2 and again[1].plan_id == plans[0].plan_id
    c.dispatcher.heard("robot-0", plans[0].plan_id, 1)  # now it drives it
    c.dispatcher.resend_unheard(sent + 3 * PLAN_RESEND_S)
    assert len([m for _, m in c.sent if isinstance(m, Plan)]) == 2


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
    # its pose never heard: no body to plan round (test_a_body_in_the_way_is_planned_round)
    job.robots["robot-0"].xy = None
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


def test_a_chain_swept_to_its_end_is_done_and_a_task_left_unswept_goes_back_as_tried(
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
    # robot-0, the only robot, has tried it: nobody is left to sell it to, and it is named
    assert job.tasks["t01.1"].tried == {"robot-0"}
    c.bidding = {"robot-0": 1.0}
    c.market.auction(c.auctioneer)
    assert job.tasks["t01.1"].state == "unreachable"
    assert all("t01.1" not in s.lot.tasks for s in c.sales)
    assert [t for _, t, _ in c.events("unreachable")] == ["t01.1"]


def _lane(tid: str, y: float, x0: float = 0.4, x1: float = 3.6) -> Task:
    path = np.column_stack([np.linspace(x0, x1, 9), np.full(9, y)])
    return Task(tid, path, 0.3 * (x1 - x0), 2.0 * (x1 - x0), (1,))


def test_a_body_in_the_way_is_planned_round_and_its_floor_is_blocked(
    planner: TaskPlanner,
) -> None:
    """Three lanes across the small world's open floor (below its table); robot-1 dies on the
    middle one. Everyone's plan is made round its body: the lanes near it are taken back from
    their owner and replaced by what can be driven round it, and the stretch under it is
    blocked until robot-1 is heard from again."""
    c = Coordinator(planner, ["robot-0", "robot-1", "robot-2"])
    job = c.job
    job.tasks.clear()
    job.add_tasks((_lane("t00", 0.6), _lane("t01", 0.85), _lane("t02", 1.1)))
    job.award("t00", "robot-0", False)
    job.award("t01", "robot-0", False)
    job.award("t02", "robot-2", False)
    job.robots["robot-0"].xy = (0.4, 0.6)
    job.robots["robot-1"].xy = (2.0, 0.85)
    c.dispatcher.plans["robot-0"] = Plan(0.0, 1, "t00", job.tasks["t00"].task.path, 0)
    try:
        c.market.lose("robot-1", "its liveliness token is gone")
        assert c.events("body")[0][:2] == ("robot-1", "")
        # robot-0's lanes both pass the body: taken back with the plan, the robot stops
        assert job.queue("robot-0") == [] and "robot-0" not in c.dispatcher.plans
        assert job.tasks["t00"].state == REPLACED and job.tasks["t01"].state == REPLACED
        # t02 passes 0.25 m from the body: robot-2 loses it too, and gets its parts back
        assert job.tasks["t02"].state == REPLACED
        made = {t: r for t, r in job.tasks.items() if r.parent in ("t00", "t01", "t02")}
        blocked = [r for r in made.values() if r.state == "blocked"]
        assert blocked and all(r.blocked_by == "robot-1" for r in blocked)
        drivable = [r for r in made.values() if r.state == OPEN]
        reach = planner.body_radius + planner.centre_clearance - planner.grid.resolution
        for rec in drivable:
            pts = densify(rec.task.path, 0.01)
            assert np.hypot(*(pts - [2.0, 0.85]).T).min() >= reach
        # the middle lane cannot be driven past the body on its own line: two parts, or one
        # part round it; either way nothing of the open work comes near the body
        assert sum(r.task.area_m2 for r in blocked) < job.tasks["t01"].task.area_m2
        # robot-1 is back: its body no longer blocks anything
        c.market.rejoined("robot-1")
        assert all(r.state == OPEN for r in blocked)
        assert not planner.near_bodies(np.array([[2.0, 0.85], [2.01, 0.85]]))
    finally:
        planner.set_bodies(np.zeros((0, 2)))


def test_the_parts_replacing_a_lost_robots_work_round_its_body_are_reassigned(
    planner: TaskPlanner,
) -> None:
    """robot-1 dies on its own lane: the lane is reopened, then replaced by parts round the
    body; the parts are what is re-sold, as reassignments timed from the loss, and the
    recovery bench counts the lost work re-sold once they are."""
    c = Coordinator(planner, ["robot-0", "robot-1", "robot-2"])
    job = c.job
    job.tasks.clear()
    job.add_tasks((_lane("t00", 0.6), _lane("t01", 0.85)))
    job.award("t00", "robot-0", False)
    job.award("t01", "robot-1", False)
    job.robots["robot-1"].xy = (2.0, 0.85)
    try:
        c.market.lose("robot-1", "its liveliness token is gone")
        c.bidding = {"robot-0": 10.0, "robot-2": 20.0}
        c.market.auction(c.auctioneer)
        parts = [t for t, r in job.tasks.items() if r.parent == "t01" and r.state != "blocked"]
        assert parts and job.tasks["t01"].state == REPLACED
        reassigned = {t for _, t, _ in c.events("reassigned")}
        assert set(parts) <= reassigned and "t01" not in reassigned
        assert "t01" not in {t for _, t, _ in c.events("awarded")}
        events = [
            {"kind": m.kind, "task": m.task, "detail": m.detail}
            for _, m in c.sent
            if isinstance(m, FleetEvent)
        ]
        assert to_reassign(events, {"t01"}) == set(parts)
        assert to_reassign(events, {"t05"}) == {"t05"}
    finally:
        planner.set_bodies(np.zeros((0, 2)))


def test_a_lot_replaced_round_a_body_while_its_round_runs_is_not_sold(
    planner: TaskPlanner,
) -> None:
    """t00 is on sale when robot-1 dies beside it: while the round waits for bids, t00 is
    replaced by parts round the body. The round's bids for t00 may not win it (the coordinator
    crashed on awarding a replaced task); the parts are sold instead."""
    c = Coordinator(planner, ["robot-0", "robot-1", "robot-2"])
    job = c.job
    job.tasks.clear()
    job.add_tasks((_lane("t00", 0.6), _lane("t01", 0.85)))
    job.award("t01", "robot-1", False)
    job.robots["robot-1"].xy = (2.0, 0.85)
    c.bidding = {"robot-0": 10.0, "robot-2": 20.0}
    answer = c.publish

    def publish(key: str, msg: Message, control: bool) -> None:
        if isinstance(msg, AuctionCall) and job.robots["robot-1"].liveness != LOST:
            c.market.lose("robot-1", "its liveliness token is gone")
        answer(key, msg, control)

    c.publish = publish  # type: ignore[method-assign]
    c.auctioneer.publish = publish
    try:
        c.market.auction(c.auctioneer)
        assert job.tasks["t00"].state == REPLACED and job.tasks["t00"].owner is None
        parts = [t for t, r in job.tasks.items() if r.parent in ("t00", "t01")]
        sold = [t for s in c.sales for t in s.lot.tasks]
        assert "t00" not in sold
        assert {t for t in parts if job.tasks[t].state != "blocked"} <= set(sold)
    finally:
        planner.set_bodies(np.zeros((0, 2)))


def test_work_lost_twice_is_on_the_next_region_sale_once(planner: TaskPlanner) -> None:
    """robot-0 is lost while an auction runs: its work waits for the next region sale, but the
    running auction sells it task by task to robot-1. robot-1 is lost too: the same tasks are
    reopened again. The next sale holds each once (a chaos run's coordinator died on a region
    holding t01 twice: ValueError, t01 is assigned, not open)."""
    c = Coordinator(planner, ["robot-0", "robot-1", "robot-2"])
    job = c.job
    for tid in ("t00", "t01", "t02"):
        job.award(tid, "robot-0", False)
    c.awards.send()
    job.robots["robot-0"].xy = None  # no body to plan round
    c.bidding = {"robot-0": 1.0, "robot-1": 10.0, "robot-2": 20.0}

    def lose_robot_0(_call: AuctionCall) -> None:
        if job.robots["robot-0"].liveness != LOST:
            c.market.lose("robot-0", "its liveliness token is gone")

    c.on_call = lose_robot_0
    c.market.auction(c.auctioneer)
    assert all(job.tasks[f"t0{i}"].owner == "robot-1" for i in range(6))

    assert job.finish("robot-1", "t03")  # not all open: no first allocation
    job.robots["robot-1"].xy = None
    c.market.lose("robot-1", "no heartbeat for 1.0 s")
    c.sales.clear()
    c.market.auction(c.auctioneer)
    sold = [t for s in c.sales for t in s.lot.tasks]
    assert sorted(sold) == ["t00", "t01", "t02", "t04", "t05"]
    assert all(job.tasks[t].owner == "robot-2" for t in sold)


def test_a_robot_lost_between_the_rounds_of_a_long_auction_wins_nothing_after(
    planner: TaskPlanner,
) -> None:
    """The coordinator's heartbeat watch runs before each round of an auction, not only after
    it: a robot that falls silent while many lots are sold (a link down for 5 s hid in a 5.7 s
    auction) is lost at the next round and wins no more lots."""
    c = Coordinator(planner, ["robot-0", "robot-1"])
    c.bidding = {"robot-0": 30.0, "robot-1": 10.0}
    rounds: list[int] = []

    def watch() -> None:
        rounds.append(len(rounds))
        if len(rounds) == 3 and c.job.robots["robot-1"].liveness != LOST:
            c.market.lose("robot-1", "no heartbeat for 1.2 s")

    c.market.region_sale = []
    for tid in c.job.tasks:
        c.job.tasks[tid].state = OPEN
    c.market.auction(c.auctioneer, watch)
    winners = [s.best.robot for s in c.sales]
    assert len(rounds) >= 3 and winners[:2] == ["robot-1", "robot-1"]
    assert set(winners[2:]) == {"robot-0"}
    assert all(r.owner == "robot-0" for r in c.job.tasks.values() if r.owner is not None)


def test_every_task_a_body_takes_back_is_saved_in_its_new_state(
    planner: TaskPlanner, tmp_path: Path
) -> None:
    """robot-0 has swept part of t00 when robot-1 dies on its lane: t00 is replaced by its
    remainder, planned round the body. The store holds t00 as replaced, not as still assigned
    (a resumed coordinator, and report.json, read the job from it)."""
    c = Coordinator(planner, ["robot-0", "robot-1", "robot-2"])
    store = JobStore(tmp_path / "job.sqlite")
    c.journal.store = store
    job = c.job
    job.tasks.clear()
    job.add_tasks((_lane("t00", 0.85), _lane("t01", 1.6)))
    job.award("t00", "robot-0", False)
    pieces = job.tasks["t00"].task.pieces
    assert job.progress("robot-0", "t00", np.array([1] + [0] * (pieces - 1), dtype=np.uint8))
    c.journal.save_tasks("t00", "t01")
    job.robots["robot-1"].xy = (2.0, 0.85)
    try:
        c.market.lose("robot-1", "its liveliness token is gone")
        assert job.tasks["t00"].state == REPLACED and job.tasks["t00.1"].parent == "t00"
        saved = Job(CoverageParams(), ROBOT, 0.0)
        store.load_job(saved)
        assert {t: r.state for t, r in saved.tasks.items()} == {
            t: r.state for t, r in job.tasks.items()
        }
    finally:
        planner.set_bodies(np.zeros((0, 2)))
        store.close()


def test_a_stuck_robots_work_is_sold_to_an_idle_one(planner: TaskPlanner, tmp_path: Path) -> None:
    """robot-0 is alive and reports its plan, but reaches no waypoint of it for stall_s while
    it escapes and gives them up one by one: its work goes back on sale (saved in its new
    states), and although it bids lowest, idle robot-1 wins what robot-0 was driving."""
    c = Coordinator(planner, ["robot-0", "robot-1"])
    c.journal.store = store = JobStore(tmp_path / "job.sqlite")
    c.market.stall_s = 30.0
    job = c.job
    job.award("t00", "robot-0", False)
    job.award("t01", "robot-0", False)
    c.journal.save_tasks(*job.tasks)
    job.progress("robot-0", "t00", np.array([1, 0, 0, 0], dtype=np.uint8))
    c.dispatcher.plans["robot-0"] = Plan(0.0, 7, "t00", job.tasks["t00"].task.path, 0)

    def report(at: float, waypoint: int, skipped: int, state: str = "blocked") -> None:
        c.journal.heard(at)
        c.market.observe(
            "robot-0", RobotStatus(at, state, "t00", 0.2, waypoint, 5, 0.0, 0, skipped, 7)
        )
        c.market.check_stalls()

    report(10.0, 2, 0, "driving")
    report(25.0, 3, 1)  # a waypoint given up is no progress
    report(35.0, 4, 2)
    assert c.events("stuck") == []  # holding or not, 30 s have not passed since 10 s
    report(40.5, 5, 3)
    assert [r for r, _, _ in c.events("stuck")] == ["robot-0"]
    assert job.queue("robot-0") == [] and "robot-0" not in c.dispatcher.plans
    rest = next(t for t, r in job.tasks.items() if r.parent == "t00")
    assert job.tasks[rest].tried == {"robot-0"} and job.tasks["t01"].state == OPEN
    saved = Job(CoverageParams(), ROBOT, 0.0)
    store.load_job(saved)
    assert {t: r.state for t, r in saved.tasks.items()} == {
        t: r.state for t, r in job.tasks.items()
    }

    c.bidding = {"robot-0": 1.0, "robot-1": 30.0}
    c.market.auction(c.auctioneer)
    assert job.tasks[rest].owner == "robot-1"
    assert job.tasks["t01"].owner in ("robot-0", "robot-1")
    store.close()


def test_holding_for_a_peer_is_not_being_stuck(planner: TaskPlanner) -> None:
    c = Coordinator(planner, ["robot-0", "robot-1"])
    c.market.stall_s = 30.0
    c.job.award("t00", "robot-0", False)
    c.dispatcher.plans["robot-0"] = Plan(0.0, 7, "t00", c.job.tasks["t00"].task.path, 0)
    for at in range(0, 100, 5):
        c.journal.heard(float(at))
        c.market.observe("robot-0", RobotStatus(at, "holding", "t00", 0.2, 2, 5, 0.0, 0, 0, 7))
        c.market.check_stalls()
    assert c.events("stuck") == []


def test_a_slow_robot_that_gets_nearer_its_waypoint_is_not_stuck(planner: TaskPlanner) -> None:
    """A long transit driven slowly (giving way, say) reaches no waypoint for a minute, but
    comes nearer the next one all the time: that is progress."""
    c = Coordinator(planner, ["robot-0", "robot-1"])
    c.market.stall_s, c.market.stall_progress_m = 30.0, 0.1
    c.job.award("t00", "robot-0", False)
    path = np.array([[0.0, 0.0], [20.0, 0.0]])
    c.dispatcher.plans["robot-0"] = Plan(0.0, 7, "t00", path, 0)
    for at in range(0, 120, 5):
        c.job.robots["robot-0"].xy = (0.05 * at, 0.0)
        c.journal.heard(float(at))
        c.market.observe("robot-0", RobotStatus(at, "driving", "t00", 0.1, 1, 2, 0.0, 0, 0, 7))
        c.market.check_stalls()
    assert c.events("stuck") == []
    # the same robot, standing still: stuck once stall_s has passed
    for at in range(120, 160, 5):
        c.journal.heard(float(at))
        c.market.observe("robot-0", RobotStatus(at, "driving", "t00", 0.1, 1, 2, 0.0, 0, 0, 7))
        c.market.check_stalls()
    assert [r for r, _, _ in c.events("stuck")] == ["robot-0"]


def test_a_new_job_sells_the_whole_floor_again_as_a_first_allocation(
    planner: TaskPlanner, tmp_path: Path
) -> None:
    """``--loop``: the job finished, the next starts: every task open again (none of the old
    job's state, remainders or plans left), the robots and their award numbers kept, so the
    agents take the new awards, and the whole floor sold as regions again."""
    c = Coordinator(planner, ["robot-0", "robot-1"])
    store = JobStore(tmp_path / "state.sqlite", fleet="test", world="small", robots=2)
    c.journal.store = store
    c.bidding = {"robot-0": 1.0, "robot-1": 2.0}
    c.market.auction(c.auctioneer)
    c.dispatcher.dispatch()
    for rid in ("robot-0", "robot-1"):
        for rec in c.job.queue(rid):
            c.job.finish(rid, rec.task.id)
    c.job.tasks["t05"].state = REPLACED  # its remainder t05.1 was done by another
    c.job.tasks["t05.1"] = c.job.tasks["t05"].__class__(_task(5), DONE)
    assert c.job.finished and c.dispatcher.plans
    seqs = {rid: r.award_seq for rid, r in c.job.robots.items()}
    sold_before = len(c.sales)
    floor = SimpleNamespace(tasks=lambda: tuple(_task(i) for i in range(6)))
    assert next_job(c.market, floor, c.market.lock) == "auction"  # type: ignore[arg-type]
    assert sorted(c.job.tasks) == [f"t{i:02d}" for i in range(6)]
    assert all(rec.state == OPEN for rec in c.job.tasks.values())
    assert not c.dispatcher.plans and c.market.need_auction
    assert sorted(r[0] for r in store.db.execute("SELECT id FROM tasks")) == sorted(c.job.tasks)
    assert store.plans() == {}
    c.market.auction(c.auctioneer)
    assert not c.job.open_tasks() and len(c.sales) - sold_before == 2  # one region per robot
    winners = {s.best.robot for s in c.sales[sold_before:]}
    assert all(c.job.robots[rid].award_seq > seqs[rid] for rid in winners)
    store.close()


def _stall(c: Coordinator, start: float, peer_xy: tuple[float, float]) -> None:
    """robot-0 reports plan 7 on t00 every 5 s from ``start`` without getting anywhere while
    robot-1 stands at ``peer_xy``, until stall_s has passed."""
    c.job.robots["robot-1"].xy = peer_xy
    for at in np.arange(start, start + 45.0, 5.0):
        c.journal.heard(float(at))
        c.market.observe(
            "robot-0", RobotStatus(float(at), "blocked", "t00", 0.2, 2, 5, 0.0, 0, 0, 7)
        )
        c.market.check_stalls()


@pytest.mark.parametrize(
    ("peer_xy", "tried"), [((0.45, 0.0), frozenset()), ((3.0, 0.0), frozenset({"robot-0"}))]
)
def test_a_robot_a_peer_held_up_has_not_tried_its_task(
    planner: TaskPlanner, peer_xy: tuple[float, float], tried: frozenset[str]
) -> None:
    """robot-0 stalls on t00 with robot-1 0.45 m away (two robots in a narrow way): t00 goes
    back to the market not as tried by robot-0; with robot-1 3 m away it is robot-0's own
    failure, and t00 is tried by it."""
    c = Coordinator(planner, ["robot-0", "robot-1"])
    c.market.stall_s = 30.0
    c.job.award("t00", "robot-0", False)
    c.dispatcher.plans["robot-0"] = Plan(0.0, 7, "t00", c.job.tasks["t00"].task.path, 0)
    _stall(c, 0.0, peer_xy)
    assert [r for r, _, _ in c.events("stuck")] == ["robot-0"]
    assert c.job.tasks["t00"].state == OPEN and c.job.tasks["t00"].tried == tried


def test_a_peer_holds_a_robot_up_on_a_task_once(planner: TaskPlanner) -> None:
    """The same two robots meet on t00 a second time: now robot-0 has tried it, so two robots
    that keep holding each other there end as one alone would, not in a loop."""
    c = Coordinator(planner, ["robot-0", "robot-1"])
    c.market.stall_s = 30.0
    for round_, start in enumerate((0.0, 100.0)):
        c.job.award("t00", "robot-0", False)
        c.dispatcher.plans["robot-0"] = Plan(0.0, 7, "t00", c.job.tasks["t00"].task.path, 0)
        _stall(c, start, (0.45, 0.0))
        assert c.job.tasks["t00"].tried == (frozenset({"robot-0"}) if round_ else frozenset())
