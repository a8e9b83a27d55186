"""The coordinator process: owns the job — who cleans what — and runs the market.

Phases: ``gathering`` (waiting for the expected robots to be ready), ``auction`` (the first
allocation), ``cleaning``, ``done`` (every task done). The job's rules live in
:class:`fleet.coordinator.job.Job`; the pricing in ``planners.auction``; this shell moves
messages and keeps the job on disk (:class:`fleet.coordinator.store.JobStore`).

Market (sequential single-item auctions, Koenig et al. 2006): each round calls every lot on
sale on ``coord/task/<lot>`` — a region of consecutive tasks (the first allocation, and the
work a lost robot leaves: one region per robot) or a single task; every robot in the market
answers each with a :class:`Bid` priced from its own pose and commitments; the best bid
(``coordinator.objective``) wins, the winner gets its whole queue on ``coord/award/<robot>``
and acknowledges it, and the next round calls what is left. Bids that are late (another
round), duplicate, malformed, or from a robot that is not in the market are counted and
ignored. Each robot gets one plan for the run of its queue that follows on without a transit.
The coordinator never reads truth.

Recovery: a robot is lost when its liveliness token goes (a dead process) or its wall-clock
heartbeat is silent for ``coordinator.heartbeat_timeout_s`` (a hung one). The unswept remainder
of its task and its unstarted tasks are auctioned again at once. A robot heard from again
rejoins with an empty queue and bids afresh; whenever a robot runs out of work while others
hold unstarted tasks, the back half of each queue is withdrawn and auctioned again (a task
boundary for all).
"""

from __future__ import annotations

import logging
import threading
import time

from fleet.bus import Bus
from fleet.coordinator.auctioneer import Auctioneer, Sale
from fleet.coordinator.awards import Awards
from fleet.coordinator.dispatcher import Dispatcher
from fleet.coordinator.job import ASSIGNED, LOST, REJOINED, GivenUpWaypoints, Job
from fleet.coordinator.journal import Journal
from fleet.coordinator.planning import TaskPlanner
from fleet.coordinator.store import JobStore
from fleet.coordinator.transits import TransitPlanner
from fleet.floor_map import pack_grid
from fleet.params import CoordinatorParams
from fleet.plan_chain import (
    chain_pieces,
    piece_count,
)
from fleet.protocol import (
    AwardAck,
    Bid,
    FleetState,
    Heartbeat,
    Plan,
    PoseEstimate,
    Request,
    RobotStatus,
)
from planners import auction

log = logging.getLogger("coordinator")

LOOP_S = 0.05
STATE_PERIOD_S = 0.5
RESEND_S = 0.5
PERSIST_ROBOTS_S = 1.0


class Coordinator:
    def __init__(
        self,
        bus: Bus,
        planner: TaskPlanner,
        expected: int,
        params: CoordinatorParams,
        store: JobStore | None = None,
        transits: TransitPlanner | None = None,
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
        resumed = self._load(store)
        meta = resumed or {}
        self.journal = Journal(
            self.job, store, self.keys, bus.publish, float(meta.get("clock", 0.0))
        )
        self.dispatcher = Dispatcher(
            self.journal, planner, transits, params, self.keys, bus.publish
        )
        self.awards = Awards(self.journal, self.keys, bus.publish)
        self.phase = "gathering"
        self.given_up = GivenUpWaypoints()
        self.need_auction = False
        self.lost_at: dict[str, float] = {}
        # tasks to sell as regions in the next auction: a lost robot's run of the tour
        self.region_sale: list[str] = []
        # the idle-robot rebalance runs once per change of who works: a robot that wins its
        # withdrawn tasks back must not be asked again and again
        self.version = 0
        self.balanced_version = -1
        self.auctioneer = Auctioneer(
            self.keys,
            bus.publish,
            params,
            self._sell,
            self.stop,
            int(meta.get("round_seq", 0)),
            meta.get("rejected_bids", {}),  # type: ignore[arg-type]
        )
        if resumed is not None:
            assert store is not None
            self._resume(store, resumed)
        bus.subscribe(self.keys.all_robots("pose"), PoseEstimate, self._on_pose)
        bus.subscribe(self.keys.all_robots("status"), RobotStatus, self._on_status)
        bus.subscribe(self.keys.all_robots("heartbeat"), Heartbeat, self._on_heartbeat)
        bus.subscribe(self.keys.all_bids(), Bid, self.auctioneer.on_bid)
        bus.subscribe(self.keys.ack("*"), AwardAck, self._on_ack)
        bus.serve(self.keys.plan("*"), Request, self._on_plan_query)
        floor = pack_grid(planner.grid)
        bus.serve(self.keys.floor_map(), Request, lambda _req: floor)
        bus.watch_alive("agent", self._on_join, self._on_leave)

    # ---- restart ------------------------------------------------------------------------

    def _load(self, store: JobStore | None) -> dict[str, object] | None:
        """Fill the job from ``store``; its counters if it holds a job to resume, else None."""
        if store is None:
            return None
        store.load_job(self.job)
        return store.meta() if self.job.tasks else None

    def _resume(self, store: JobStore, meta: dict[str, object]) -> None:
        self.dispatcher.resume(store.plans(), int(meta.get("plan_seq", 0)))
        self.phase = str(meta.get("phase", "cleaning"))
        self.given_up = GivenUpWaypoints.from_json(meta.get("given_up_waypoints"))
        now = time.time()
        for r in self.job.robots.values():
            # robots are heard from again within a heartbeat; until then none counts as silent,
            # and those in the market stay there (their first heartbeat is no news to rebalance)
            r.heartbeat_wall = now
            r.ready = r.liveness != LOST
        self.awards.resume()
        self.need_auction = bool(self.job.open_tasks())
        log.info(
            "resumed the job from %s: %s, phase %s",
            store.path,
            ", ".join(f"{v} {k}" for k, v in self.job.counts().items()),
            self.phase,
        )
        self.journal.event("resumed", "", "", f"{len(self.job.tasks)} tasks")

    # ---- bus callbacks ------------------------------------------------------------------

    def _on_pose(self, key: str, msg: PoseEstimate) -> None:
        rid = self.keys.robot_of(key)
        with self.lock:
            self.journal.heard(msg.stamp)
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
                self.journal.event("rejoined", rid, "", "heard from again; bids afresh")
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
                self.journal.event("joined", rid, "", "")

    def _on_leave(self, rid: str) -> None:
        with self.lock:
            if rid in self.job.robots and self.job.robots[rid].liveness != LOST:
                self._lose(rid, "its liveliness token is gone")

    def _on_status(self, key: str, msg: RobotStatus) -> None:
        rid = self.keys.robot_of(key)
        with self.lock:
            r = self.job.robot(rid)
            r.state, r.task, r.progress = msg.state, msg.task, msg.progress
            self.dispatcher.heard(rid, msg.plan_id, msg.waypoint)
            if msg.plan_id >= 0 and self.given_up.report(rid, msg.plan_id, msg.skipped):
                log.warning("%s has given up %d waypoint(s)", rid, self.given_up.by_robot[rid])
            plan = self.dispatcher.plans.get(rid)
            if plan is None or msg.plan_id != plan.plan_id or r.liveness == LOST:
                return
            if len(msg.swept) != piece_count(len(plan.waypoints), plan.sweep_from):
                return
            for tid, (a, b) in chain_pieces(plan):
                swept = msg.swept[a:b]
                if self.job.progress(rid, tid, swept):
                    self.journal.save_tasks(tid)
                rec = self.job.tasks.get(tid)
                held = rec is not None and rec.state == ASSIGNED and rec.owner == rid
                if held and (msg.state == "done" or swept.all()):
                    again = None if swept.all() else self.job.give_back(rid, tid)
                    if again is None:
                        self.job.finish(rid, tid)
                        self.journal.event("done", rid, tid, "")
                    else:
                        self.journal.event(
                            "withdrawn", rid, tid, f"pieces given up: once more as {again}"
                        )
                        self.need_auction = True
                    self.version += 1
                    self.journal.save_tasks(*(t for t in (tid, again) if t is not None))
                    self.wake.set()

    def _on_ack(self, key: str, msg: AwardAck) -> None:
        rid = self.keys.robot_of(key)
        with self.lock:
            if self.awards.acked(rid, msg):
                self.wake.set()

    def _on_plan_query(self, req: Request) -> Plan:
        with self.lock:
            plan = self.dispatcher.current(req.sender)
        if plan is None:
            raise LookupError(f"no plan for {req.sender} now")
        return plan

    # ---- job changes (called with self.lock held) ---------------------------------------

    def _lose(self, rid: str, why: str) -> None:
        reopened, made = self.job.lose(rid)
        self.version += 1
        self.journal.event("lost", rid, "", why)
        now = time.monotonic()
        self.lost_at.update(dict.fromkeys(reopened, now))
        self.region_sale += reopened
        for tid in reopened:
            self.journal.event("reopened", rid, tid, "remainder" if tid in made else "unstarted")
        changed = [r.task.id for r in self.job.tasks.values() if r.owner is None]
        self.journal.save_tasks(*changed)
        self.dispatcher.forget(rid)
        self.awards.send()
        self.need_auction = True
        self.wake.set()

    def _rebalance(self) -> None:
        """Withdraw the unstarted tasks for a new auction. A robot keeps the task it drives; its
        plan is cut before the first task it gave up, under the same plan id, so it drives on
        to there without a stop. (A robot that has just entered the next task of its plan when
        the cut arrives stops there; it has swept a piece or two of a task now sold again.)"""
        self.version += 1
        self.balanced_version = self.version
        withdrawn = self.job.withdraw_unstarted()
        for tid in withdrawn:
            self.journal.event("withdrawn", "", tid, "back to the market")
        self.journal.save_tasks(*withdrawn)
        self.dispatcher.cut(withdrawn)
        self.awards.send()
        self.need_auction = True
        self.wake.set()

    # ---- the market ---------------------------------------------------------------------

    def _lots(self, regions: tuple[auction.Lot, ...]) -> dict[str, auction.Lot]:
        """What the next round sells: the regions none of whose tasks is sold yet, then every
        open task on its own."""
        open_ids = {r.task.id for r in self.job.open_tasks()}
        unsold = {lot.id: lot for lot in regions if set(lot.tasks) <= open_ids}
        if unsold:
            return unsold
        return {tid: auction.task_lot(self.job.tasks[tid].task) for tid in open_ids}

    def _auction(self) -> None:
        """Sequential single-item auctions over the bus until nothing is open or no robot bids.

        Runs of the tour are sold as regions, one per robot in the market
        (``planners.auction.regions``): all tasks in the first allocation, and the work a lost
        robot leaves; everything else task by task."""
        t0 = time.monotonic()
        awarded = 0
        committed: list[float] = []
        with self.lock:
            first = all(r.state == "open" for r in self.job.tasks.values())
            if first:
                self.region_sale = list(self.job.tasks)
            sale = sorted(
                (t for t in self.region_sale if self.job.tasks[t].state == "open"), key=_tour_key
            )
            self.region_sale = []
            bidders = self.job.market()
            runs = [self.job.tasks[t].task for t in sale]
        regions = auction.regions(runs, len(bidders)) if bidders else ()
        while not self.stop.is_set():
            with self.lock:
                self.need_auction = False
                lots = self._lots(regions)
                bidders = frozenset(self.job.market())
            if not lots or not bidders:
                break
            rnd = self.auctioneer.call(self.journal.clock, lots, bidders)
            with self.lock:
                sale = self.auctioneer.award(rnd, set(self.job.market()))
            if sale is None:
                break
            committed.append(sale.best.total_s)
            awarded += 1
        if first and committed:
            with self.lock:
                if not self.job.open_tasks():
                    self._estimate(max(committed))
        if awarded:
            ms = 1e3 * (time.monotonic() - t0)
            log.info("auction: %d lots sold in %.0f ms", awarded, ms)
            with self.lock:
                self.journal.event("auction", "", "", f"{awarded} lots in {ms:.0f} ms")

    def _estimate(self, makespan_s: float) -> None:
        """The job's makespan as the first allocation prices it: the longest of the winners'
        committed times (travel from where each stood, and the cleaning time of what it won)."""
        log.info("the first allocation's makespan estimate: %.1f s", makespan_s)
        self.journal.event("estimated", "", "", f"makespan {makespan_s:.1f} s")
        self.journal.set_meta(estimate_s=round(makespan_s, 2))

    def _sell(self, sale: Sale) -> None:
        """The auctioneer's result: award the lot's tasks to the winner (in the order it drives
        them), log the round, send the winner its queue."""
        lot, best = sale.lot, sale.best
        order = lot.tasks[::-1] if best.reverse else lot.tasks
        for tid in order:
            self.job.award(tid, best.robot, best.reverse)
            lost_at = self.lost_at.pop(tid, None)
            if lost_at is None:
                self.journal.event("awarded", best.robot, tid, f"{lot.id}: {best.total_s:.1f} s")
            else:
                after = time.monotonic() - lost_at
                self.journal.event("reassigned", best.robot, tid, f"{after:.3f} s after the loss")
        self.journal.save_tasks(*order)
        self.journal.add_bids(
            [
                (
                    sale.round,
                    b.task,
                    b.robot,
                    b.marginal_s,
                    b.total_s,
                    int(b.reverse),
                    int(b.task == best.task and b.robot == best.robot),
                )
                for b in sale.bids
            ]
        )
        self.journal.set_meta(round_seq=sale.round)
        self.awards.send()

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
        """Plan the tasks (unless resumed) while the robots start, then run the job."""
        if not self.job.tasks:
            self._plan_tasks()
        gather_start = time.monotonic()
        last_state = last_robots = 0.0
        while not self.stop.is_set():
            self.wake.wait(LOOP_S)
            self.wake.clear()
            auction_due = False
            with self.lock:
                if self.phase == "gathering":
                    if self._gathered(time.monotonic() - gather_start, grace_s):
                        self.phase = "auction"
                        self.need_auction = True
                        self.journal.set_meta(phase=self.phase)
                else:
                    self._check_heartbeats()
                    idle = [rid for rid in self.job.market() if self.job.current(rid) is None]
                    queued = any(len(self.job.queue(rid)) > 1 for rid in self.job.robots)
                    if idle and queued and self.version != self.balanced_version:
                        self._rebalance()
                    auction_due = bool(idle and self.job.open_tasks())
                auction_due = auction_due or self.need_auction
            if self.phase != "gathering" and auction_due:
                self._auction()
            with self.lock:
                if self.phase != "gathering":
                    self.awards.send()
                    self.dispatcher.dispatch()
                    if self.job.finished and self.phase != "done":
                        self.phase = "done"
                        log.info(self.given_up.finished_message())
                        self.journal.event("finished", "", "", "")
                        self.journal.set_meta(phase=self.phase)
                    elif self.phase == "auction" and not self.job.open_tasks():
                        self.phase = "cleaning"
                now = time.monotonic()
                if self.store is not None and now - last_robots > PERSIST_ROBOTS_S:
                    last_robots = now
                    self.store.save_robots(list(self.job.robots.values()))
                    self.store.set_meta(
                        phase=self.phase,
                        clock=self.journal.clock,
                        rejected_bids=self.auctioneer.rejected(),
                        given_up_waypoints=self.given_up.to_json(),
                    )
                if now - last_state > STATE_PERIOD_S:
                    last_state = now
                    self._publish_state()

    def _plan_tasks(self) -> None:
        t0 = time.perf_counter()
        tasks = self.planner.tasks()
        log.info("planned %d tasks in %.2f s", len(tasks), time.perf_counter() - t0)
        with self.lock:
            self.job.add_tasks(tasks)
            self.journal.save_tasks(*self.job.tasks)
            self.journal.set_meta(expected_robots=self.expected)
            self.journal.event("planned", "", "", f"{len(tasks)} tasks")

    def _publish_state(self) -> None:
        counts = self.job.counts()
        robots = sorted(self.job.robots)
        state = FleetState(
            self.journal.clock,
            self.phase,
            robots,
            sorted(r for r in robots if self.job.current(r) is None),
            sorted(r for r in robots if self.job.robots[r].liveness == LOST),
            counts["open"],
            counts[ASSIGNED],
            counts["done"],
        )
        self.bus.publish(self.keys.coord_state(), state, control=True)


def _tour_key(task_id: str) -> tuple[int, ...]:
    """Where a task lies along the tour: "t07" → (7,), its remainder "t07.1" → (7, 1)."""
    return tuple(int(part) for part in task_id.lstrip("t").split("."))
