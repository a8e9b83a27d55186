"""The coordinator process: owns the job — who cleans what — and runs the market.

Phases: ``gathering`` (waiting for the expected robots to be ready), ``auction`` (the first
allocation), ``cleaning``, ``done`` (every task done). The job's rules live in
:class:`fleet.coordinator.job.Job`; the pricing in ``planners.auction``; this shell moves
messages and keeps the job on disk (:class:`fleet.coordinator.store.JobStore`).

Market (sequential single-item auctions, Koenig et al. 2006): each round calls every open
task on ``coord/task/<task>``; every robot in the market answers each with a :class:`Bid`
priced from its own pose and commitments; the best bid (``coordinator.objective``) wins, the
winner gets its whole queue on ``coord/award/<robot>`` and acknowledges it, and the next round
calls what is left. Bids that are late (another round), duplicate, malformed, or from a robot
that is not in the market are counted and ignored. The coordinator never reads truth.

Recovery: a robot is lost when its liveliness token goes (a dead process) or its wall-clock
heartbeat is silent for ``coordinator.heartbeat_timeout_s`` (a hung one). The unswept remainder
of its task and its unstarted tasks are auctioned again at once. A robot heard from again
rejoins with an empty queue and bids afresh; whenever a robot runs out of work while others
hold unstarted tasks, those are withdrawn and auctioned again (a task boundary for all).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import Counter
from dataclasses import dataclass

import numpy as np

from fleet.bus import Bus
from fleet.coordinator.job import ASSIGNED, LOST, REJOINED, Job
from fleet.coordinator.planning import TaskPlanner
from fleet.coordinator.store import JobStore
from fleet.params import CoordinatorParams
from fleet.protocol import (
    Award,
    AwardAck,
    Bid,
    FleetEvent,
    FleetState,
    Heartbeat,
    Plan,
    PoseEstimate,
    Request,
    RobotStatus,
    TaskCall,
)
from planners import auction

log = logging.getLogger("coordinator")

LOOP_S = 0.05
STATE_PERIOD_S = 0.5
RESEND_S = 0.5
PERSIST_ROBOTS_S = 1.0


@dataclass
class _Round:
    number: int
    tasks: frozenset[str]
    bidders: frozenset[str]


class Coordinator:
    def __init__(
        self,
        bus: Bus,
        planner: TaskPlanner,
        expected: int,
        params: CoordinatorParams,
        store: JobStore | None = None,
    ) -> None:
        self.bus = bus
        self.keys = bus.keys
        self.planner = planner
        self.expected = expected
        self.params = params
        self.store = store
        self.lock = threading.RLock()
        self.stop = threading.Event()
        self.wake = threading.Event()
        self.job = Job(planner.params)
        self.plans: dict[str, Plan] = {}
        self.sent: dict[str, tuple[str, ...]] = {}
        self.last_award_sent: dict[str, float] = {}
        self.phase = "gathering"
        self.clock = 0.0
        self.plan_seq = 0
        self.round_seq = 0
        self.rejected: Counter[str] = Counter()
        self.need_auction = False
        self.lost_at: dict[str, float] = {}
        self._round: _Round | None = None
        self._bids: dict[tuple[str, str], Bid] = {}
        self._bids_cond = threading.Condition()
        if store is not None:
            self._resume(store)
        bus.subscribe(self.keys.all_robots("pose"), PoseEstimate, self._on_pose)
        bus.subscribe(self.keys.all_robots("status"), RobotStatus, self._on_status)
        bus.subscribe(self.keys.all_robots("heartbeat"), Heartbeat, self._on_heartbeat)
        bus.subscribe(self.keys.all_bids(), Bid, self._on_bid)
        bus.subscribe(self.keys.ack("*"), AwardAck, self._on_ack)
        bus.serve(self.keys.plan("*"), Request, self._on_plan_query)
        bus.watch_alive("agent", self._on_join, self._on_leave)

    # ---- restart ------------------------------------------------------------------------

    def _resume(self, store: JobStore) -> None:
        store.load_job(self.job)
        if not self.job.tasks:
            return
        meta = store.meta()
        self.plans = store.plans()
        self.plan_seq = int(meta.get("plan_seq", 0))
        self.round_seq = int(meta.get("round_seq", 0))
        self.phase = str(meta.get("phase", "cleaning"))
        now = time.time()
        for rid, r in self.job.robots.items():
            # robots are heard from again within a heartbeat; until then none counts as silent
            r.heartbeat_wall = now
            self.sent[rid] = tuple(t.task.id for t in self.job.queue(rid))
        self.need_auction = bool(self.job.open_tasks())
        log.info(
            "resumed the job from %s: %s, phase %s",
            store.path,
            ", ".join(f"{v} {k}" for k, v in self.job.counts().items()),
            self.phase,
        )
        self._event("resumed", "", "", f"{len(self.job.tasks)} tasks")

    # ---- bus callbacks ------------------------------------------------------------------

    def _on_pose(self, key: str, msg: PoseEstimate) -> None:
        rid = self.keys.robot_of(key)
        with self.lock:
            self.clock = max(self.clock, msg.stamp)
            self.job.robot(rid).xy = (msg.x, msg.y)

    def _on_heartbeat(self, key: str, msg: Heartbeat) -> None:
        rid = self.keys.robot_of(key)
        with self.lock:
            r = self.job.robot(rid)
            r.heartbeat_wall = time.time()
            was_ready = r.ready
            r.ready = msg.ready
            if r.liveness == LOST:
                r.liveness = REJOINED
                self._event("rejoined", rid, "", "heard from again; bids afresh")
                self._rebalance()
            elif r.ready and not was_ready and self.phase != "gathering":
                self._rebalance()

    def _on_join(self, rid: str) -> None:
        with self.lock:
            known = rid in self.job.robots
            r = self.job.robot(rid)
            r.heartbeat_wall = time.time()
            if known and r.liveness == LOST:
                r.restarts += 1
            elif not known:
                self._event("joined", rid, "", "")

    def _on_leave(self, rid: str) -> None:
        with self.lock:
            if rid in self.job.robots and self.job.robots[rid].liveness != LOST:
                self._lose(rid, "its liveliness token is gone")

    def _on_status(self, key: str, msg: RobotStatus) -> None:
        rid = self.keys.robot_of(key)
        with self.lock:
            r = self.job.robot(rid)
            r.state, r.task, r.progress = msg.state, msg.task, msg.progress
            plan = self.plans.get(rid)
            if plan is None or msg.plan_id != plan.plan_id or r.liveness == LOST:
                return
            if self.job.progress(rid, plan.task, msg.swept):
                self._save_task(plan.task)
            current = self.job.current(rid)
            if msg.state == "done" and current is not None and current.task.id == plan.task:
                self.job.finish(rid, plan.task)
                self._save_task(plan.task)
                self._event("done", rid, plan.task, "")
                self.wake.set()

    def _on_ack(self, key: str, msg: AwardAck) -> None:
        rid = self.keys.robot_of(key)
        with self.lock:
            r = self.job.robots.get(rid)
            if r is not None and msg.robot == rid and msg.seq <= r.award_seq:
                r.acked_seq = max(r.acked_seq, msg.seq)
                self.wake.set()

    def _on_bid(self, key: str, msg: Bid) -> None:
        rid = self.keys.robot_of(key)
        ok_numbers = all(math.isfinite(v) and v >= 0 for v in (msg.marginal_s, msg.total_s))
        with self._bids_cond:
            rnd = self._round
            if msg.robot != rid or not ok_numbers or key != self.keys.bid(msg.task, msg.robot):
                why = "malformed"
            elif rnd is None or msg.round != rnd.number or msg.task not in rnd.tasks:
                why = "late"
            elif rid not in rnd.bidders:
                why = "not in the market"
            elif (msg.task, rid) in self._bids:
                why = "duplicate"
            else:
                self._bids[(msg.task, rid)] = msg
                self._bids_cond.notify_all()
                return
            self.rejected[why] += 1
            n = self.rejected[why]
        if n == 1 or n % 100 == 0:
            log.warning("ignored a %s bid from %s on %s (%d so far)", why, rid, msg.task, n)

    def _on_plan_query(self, req: Request) -> Plan:
        with self.lock:
            plan = self.plans.get(req.sender)
            current = self.job.current(req.sender)
        if plan is None or current is None or current.task.id != plan.task:
            raise LookupError(f"no plan for {req.sender} now")
        return plan

    # ---- job changes (called with self.lock held) ---------------------------------------

    def _event(self, kind: str, robot: str, task: str, detail: str) -> None:
        wall = time.time()
        if kind in ("lost", "rejoined", "reassigned", "withdrawn", "resumed"):
            log.info("%s %s %s %s", kind, robot, task, detail)
        if self.store is not None:
            self.store.add_event(wall, self.clock, kind, robot, task, detail)
        self.bus.publish(
            self.keys.events(), FleetEvent(self.clock, wall, kind, robot, task, detail), True
        )

    def _save_task(self, *ids: str) -> None:
        if self.store is not None:
            self.store.save_tasks([self.job.tasks[i] for i in ids])

    def _lose(self, rid: str, why: str) -> None:
        reopened, made = self.job.lose(rid)
        self._event("lost", rid, "", why)
        now = time.monotonic()
        self.lost_at.update(dict.fromkeys(reopened, now))
        for tid in reopened:
            self._event("reopened", rid, tid, "remainder" if tid in made else "unstarted")
        changed = [r.task.id for r in self.job.tasks.values() if r.owner is None]
        self._save_task(*changed)
        self.plans.pop(rid, None)
        self._publish_awards()
        self.need_auction = True
        self.wake.set()

    def _rebalance(self) -> None:
        withdrawn = self.job.withdraw_unstarted()
        for tid in withdrawn:
            self._event("withdrawn", "", tid, "back to the market")
        self._save_task(*withdrawn)
        self._publish_awards()
        self.need_auction = True
        self.wake.set()

    def _publish_awards(self, force: bool = False) -> None:
        """Send each robot its queue when it changed (or is unacknowledged and due again)."""
        now = time.monotonic()
        for rid, r in self.job.robots.items():
            queue = self.job.queue(rid)
            ids = tuple(t.task.id for t in queue)
            changed = ids != self.sent.get(rid, ())
            due = r.acked_seq < r.award_seq and now - self.last_award_sent.get(rid, 0) > RESEND_S
            if not (changed or due or force):
                continue
            if changed:
                r.award_seq += 1
                self.sent[rid] = ids
            ends = [
                (t.task.exit, t.task.entry) if t.reverse else (t.task.entry, t.task.exit)
                for t in queue
            ]
            msg = Award(
                self.clock,
                r.award_seq,
                rid,
                list(ids),
                np.array([e for e, _ in ends], dtype=float).reshape(-1, 2),
                np.array([x for _, x in ends], dtype=float).reshape(-1, 2),
                np.array([t.task.time_s for t in queue], dtype=float),
            )
            self.last_award_sent[rid] = now
            self.bus.publish(self.keys.award(rid), msg, control=True)

    # ---- the market ---------------------------------------------------------------------

    def _auction(self) -> None:
        """Sequential single-item auctions over the bus until no open task or no bidder."""
        t0 = time.monotonic()
        awarded = 0
        while not self.stop.is_set():
            with self.lock:
                self.need_auction = False
                open_tasks = {r.task.id: r.task for r in self.job.open_tasks()}
                bidders = frozenset(self.job.market())
            if not open_tasks or not bidders:
                break
            self.round_seq += 1
            rnd = _Round(self.round_seq, frozenset(open_tasks), bidders)
            with self._bids_cond:
                self._round = rnd
                self._bids = {}
            for t in open_tasks.values():
                call = TaskCall(
                    self.clock, rnd.number, t.id, *t.entry, *t.exit, t.time_s, t.area_m2
                )
                self.bus.publish(self.keys.task(t.id), call, control=True)
            deadline = time.monotonic() + self.params.bid_timeout_s
            want = len(open_tasks) * len(bidders)
            with self._bids_cond:
                while len(self._bids) < want and not self.stop.is_set():
                    left = deadline - time.monotonic()
                    if left <= 0:
                        break
                    self._bids_cond.wait(left)
                bids = dict(self._bids)
                self._round = None
            with self.lock:
                market = set(self.job.market())
                live = [b for b in bids.values() if b.robot in market]
                best = auction.winner(
                    (
                        auction.Bid(b.task, b.robot, b.marginal_s, b.total_s, b.reverse)
                        for b in live
                    ),
                    self.params.objective,
                )
                if best is None:
                    log.warning(
                        "auction round %d: no bids from %s within %.1f s",
                        rnd.number,
                        ", ".join(sorted(bidders)),
                        self.params.bid_timeout_s,
                    )
                    break
                rec = self.job.award(best.task, best.robot, best.reverse)
                self._save_task(best.task)
                if self.store is not None:
                    self.store.add_bids(
                        [
                            (
                                rnd.number,
                                b.task,
                                b.robot,
                                b.marginal_s,
                                b.total_s,
                                int(b.reverse),
                                int(b.task == best.task and b.robot == best.robot),
                            )
                            for b in live
                        ]
                    )
                    self.store.set_meta(round_seq=self.round_seq)
                lost_at = self.lost_at.pop(rec.task.id, None)
                if lost_at is None:
                    self._event("awarded", best.robot, best.task, f"{best.total_s:.1f} s")
                else:
                    after = time.monotonic() - lost_at
                    self._event(
                        "reassigned", best.robot, best.task, f"{after:.3f} s after the loss"
                    )
                self._publish_awards()
                awarded += 1
        if awarded:
            log.info("auction: %d tasks awarded in %.0f ms", awarded, 1e3 * (time.monotonic() - t0))

    def _dispatch(self) -> None:
        """Send a plan to every robot whose current task has none yet (once it has the award)."""
        for rid, r in self.job.robots.items():
            if r.liveness == LOST or r.xy is None:
                continue
            current = self.job.current(rid)
            plan = self.plans.get(rid)
            if current is None or r.acked_seq < r.award_seq:
                continue
            if plan is not None and plan.task == current.task.id:
                continue
            waypoints, sweep_from = self.planner.drive(r.xy, current.task, current.reverse)
            self.plan_seq += 1
            plan = Plan(self.clock, self.plan_seq, current.task.id, waypoints, sweep_from)
            self.plans[rid] = plan
            if self.store is not None:
                self.store.save_plan(rid, plan)
                self.store.set_meta(plan_seq=self.plan_seq)
            self.bus.publish(self.keys.plan(rid), plan, control=True)

    def _check_heartbeats(self) -> None:
        now = time.time()
        for rid, r in list(self.job.robots.items()):
            if r.liveness != LOST and now - r.heartbeat_wall > self.params.heartbeat_timeout_s:
                self._lose(rid, f"no heartbeat for {now - r.heartbeat_wall:.1f} s")

    def _gathered(self, waited: float, grace_s: float) -> bool:
        n = len(self.job.market())
        if n >= self.expected or (n > 0 and waited > grace_s):
            if n < self.expected:
                log.warning("only %d of %d robots are ready; starting with them", n, self.expected)
            return True
        return False

    # ---- main loop ----------------------------------------------------------------------

    def run(self, grace_s: float) -> None:
        gather_start = time.monotonic()
        last_state = last_robots = 0.0
        while not self.stop.is_set():
            self.wake.wait(LOOP_S)
            self.wake.clear()
            auction_due = False
            with self.lock:
                if self.phase == "gathering":
                    if self._gathered(time.monotonic() - gather_start, grace_s):
                        self._plan_tasks()
                else:
                    self._check_heartbeats()
                    idle = [rid for rid in self.job.market() if self.job.current(rid) is None]
                    queued = any(len(self.job.queue(rid)) > 1 for rid in self.job.robots)
                    if idle and queued:
                        self._rebalance()
                    auction_due = bool(idle and self.job.open_tasks())
                auction_due = auction_due or self.need_auction
            if self.phase != "gathering" and auction_due:
                self._auction()
            with self.lock:
                if self.phase != "gathering":
                    self._publish_awards()
                    self._dispatch()
                    if self.job.finished and self.phase != "done":
                        self.phase = "done"
                        log.info("every task is done: the floor is clean")
                        self._event("finished", "", "", "")
                    elif self.phase == "auction" and not self.job.open_tasks():
                        self.phase = "cleaning"
                    if self.store is not None:
                        self.store.set_meta(phase=self.phase)
                now = time.monotonic()
                if self.store is not None and now - last_robots > PERSIST_ROBOTS_S:
                    last_robots = now
                    self.store.save_robots(list(self.job.robots.values()))
                if now - last_state > STATE_PERIOD_S:
                    last_state = now
                    self._publish_state()

    def _plan_tasks(self) -> None:
        t0 = time.perf_counter()
        tasks = self.planner.tasks()
        self.job.add_tasks(tasks)
        log.info("planned %d tasks in %.2f s", len(tasks), time.perf_counter() - t0)
        if self.store is not None:
            self.store.save_tasks(list(self.job.tasks.values()))
            self.store.set_meta(expected_robots=self.expected)
        self._event("planned", "", "", f"{len(tasks)} tasks")
        self.phase = "auction"
        self.need_auction = True

    def _publish_state(self) -> None:
        counts = self.job.counts()
        robots = sorted(self.job.robots)
        state = FleetState(
            self.clock,
            self.phase,
            robots,
            sorted(r for r in robots if self.job.current(r) is None),
            sorted(r for r in robots if self.job.robots[r].liveness == LOST),
            counts["open"],
            counts[ASSIGNED],
            counts["done"],
        )
        self.bus.publish(self.keys.coord_state(), state, control=True)
