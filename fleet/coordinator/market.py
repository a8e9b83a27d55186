"""The market's side of the job: what goes on sale, and what a sale, a swept task, a lost robot
or an idle one changes.

Sequential single-item auctions (Koenig et al. 2006, :mod:`fleet.coordinator.auctioneer`): the
auction runs rounds until nothing is open or no robot bids, one lot sold per round. Runs of the
tour are sold as regions, one per robot in the market (``planners.auction.regions``): all tasks
in the first allocation, and the work a lost robot leaves; everything else task by task. The
winner's whole queue goes out as its award (:mod:`fleet.coordinator.awards`). The first
allocation's makespan (the longest of the winners' committed times) is the job's estimate.

A task is done when its pieces are swept; a plan that ends with pieces of a tour task unswept
(waypoints given up) gives them back to the market once, as a remainder (``Job.give_back``).

Recovery: a lost robot's unswept remainder and its unstarted tasks are auctioned again at once,
as regions. A robot heard from again rejoins with an empty queue and bids afresh; whenever a
robot in the market runs out of work while others hold unstarted tasks, the back half of each
queue is withdrawn and auctioned again (a task boundary for all).

Bodies: a lost robot's body stays where it stopped (its last reported pose), and everyone plans
around it: every task whose path comes near it is taken back and replaced by the runs of its
path a robot can drive, joined round the body where a transit gets round it
(:func:`planners.bodies.reroute`), and by the stretches under or behind it, which are
``blocked`` until the body goes (its robot heard from again). Transits are planned round it too.

Progress, not only liveliness: a robot that for ``coordinator.stall_s`` sim seconds reaches no
waypoint of its plan and comes no ``coordinator.stall_progress_m`` nearer the one it heads for
(holding for a peer at a shared cell aside; giving waypoints up is no progress) is stuck: the
unswept remainder of its task goes back to the market as work it has tried, and its unstarted
tasks with it (not as tried the first time a robot stalls, or ends its plan with pieces given
up, on a task after a peer came within ``PEER_NEAR_GAP_M`` of its body on that plan: two
robots that held each other up in a narrow way have learnt nothing about the task's floor,
and each may take it again once; a second time it counts); it stays in the market with no
work (it waits) and may win other work, whose plan starts with a transit planned from where
it stands. A robot that no transit takes to its task gives the task back the same way. No
robot wins a task it has tried; a task every robot in the market has tried is
``unreachable``, never counted done (see the job's rules in :mod:`fleet.coordinator.job`).
"""

from __future__ import annotations

import logging
import math
import re
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from fleet.coordinator.auctioneer import Auctioneer, Sale
from fleet.coordinator.awards import Awards
from fleet.coordinator.dispatcher import Dispatcher
from fleet.coordinator.job import ASSIGNED, LOST, OPEN, Job
from fleet.coordinator.journal import Journal
from fleet.plan_chain import chain_pieces, piece_count
from fleet.protocol import Plan, RobotStatus
from planners import auction
from planners.bodies import Rerouted

log = logging.getLogger("coordinator")
# called with the market's lock held
Hook = Callable[[], None]
# how the regions of an auction are cut (outside the market's lock)
Cut = Callable[[], tuple[auction.Lot, ...]]
# robot states in which reaching no waypoint is no sign of being stuck
WAITING_STATES = ("holding", "done", "waiting", "localizing", "unlocalized")
# how often the auction looks whether the last winner has acknowledged its award (wall s)
ACK_POLL_S = 0.002
# a peer whose centre came within two robot radii and this much (m) of a robot's held it up:
# the mutual holds seen had centres 0.35-0.54 m apart
PEER_NEAR_GAP_M = 0.3
# what a stall or give-back put down to a peer says in its event
PEER_HELD = "a peer held it up"


@dataclass
class Progress:
    """How far a robot has got along its plan: waypoints reached (not given up), the waypoint
    it heads for and the least distance to it so far, and since when (sim s) it has neither
    reached another nor come ``stall_progress_m`` nearer the one it heads for."""

    plan_id: int
    reached: int
    heading_for: int
    best_m: float
    since: float


class MarketParts(Protocol):
    """What the coordinator's parts add to the market (:class:`fleet.coordinator.parts.Parts`:
    each hook of :class:`fleet.coordinator.parts.Part` on every part, the answers combined)."""

    def regions(self, first: bool, cut: Cut) -> tuple[bool, Cut]: ...

    def lots(self) -> dict[str, auction.Lot] | None: ...

    def may_win(self, lot: auction.Lot, robot: str) -> bool: ...

    def estimate_first(self, committed: list[float]) -> bool: ...

    def after_auction(self, sold: int) -> None: ...


class Market:
    """The job's changes the market makes; each method but :meth:`auction` is called with
    ``lock`` held, and :meth:`sell` by the auctioneer, under ``lock`` too."""

    def __init__(
        self,
        journal: Journal,
        awards: Awards,
        dispatcher: Dispatcher,
        lock: threading.RLock,
        wake: threading.Event,
        stop: threading.Event,
        parts: MarketParts | None = None,
    ) -> None:
        """``wake`` is set when the job changed and the main loop should look again; ``stop``
        ends an auction between rounds; ``parts``: what the coordinator's parts add (none
        without)."""
        self.parts = parts
        self.journal = journal
        self.job = journal.job
        self.awards = awards
        self.dispatcher = dispatcher
        self.lock = lock
        self.wake = wake
        self.stop = stop
        self.need_auction = False
        self.lost_at: dict[str, float] = {}
        # tasks to sell as regions in the next auction, each once: a lost robot's run of the tour
        self.region_sale: list[str] = []
        # the idle-robot rebalance runs once per change of who works: a robot that wins its
        # withdrawn tasks back must not be asked again and again
        self.version = 0
        self.balanced_version = -1
        # lost robots' bodies, where they last reported themselves
        self.bodies: dict[str, tuple[float, float]] = {}
        self.progress: dict[str, Progress] = {}
        # the plan on which a peer last came near each robot, and the (robot, task) stalls
        # forgiven as a peer's doing (each once)
        self.met: dict[str, int] = {}
        self.forgiven: set[tuple[str, str]] = set()
        self.stall_s = math.inf
        self.stall_progress_m = 0.0

    # ---- selling --------------------------------------------------------------------------

    def auction(self, auctioneer: Auctioneer, each_round: Hook = lambda: None) -> None:
        """Sequential single-item auctions over the bus until nothing is open or no robot bids,
        ``each_round`` (the heartbeat watch, else held up by a long auction) called first in
        each."""
        t0 = time.monotonic()
        committed: list[float] = []
        with self.lock:
            first, cut = self._regions()
        regions = cut()
        while not self.stop.is_set():
            with self.lock:
                each_round()
                self.need_auction = False
                self._settle()
                lots = self._lots(regions)
                round_bidders = frozenset(self._bidders())
            if not lots or not round_bidders:
                break
            rnd = auctioneer.call(self.journal.clock, lots, round_bidders)
            with self.lock:
                if changed(self.job, rnd.lots):
                    # a robot lost meanwhile took lots off the market: call what is on it now
                    continue
                sale = auctioneer.award(rnd, set(self.job.market()), self._untried)
            if sale is None:
                break
            committed.append(sale.best.total_s)
            await_ack(self.lock, self.job, sale.best.robot, auctioneer.params.bid_timeout_s)
        if first:
            with self.lock:
                self.estimate_first(committed)
        if committed:
            ms = 1e3 * (time.monotonic() - t0)
            log.info("auction: %d lots sold in %.0f ms", len(committed), ms)
            with self.lock:
                self.journal.event("auction", "", "", f"{len(committed)} lots in {ms:.0f} ms")
        if self.parts is not None:
            with self.lock:
                self.parts.after_auction(len(committed))

    def estimate_first(self, committed: list[float]) -> None:
        """The job's estimate: the longest of the winners' ``committed`` times, if all sold
        (unless a part tells it)."""
        if self.parts is not None and self.parts.estimate_first(committed):
            return
        if committed and not self.job.open_tasks():
            estimate(self.journal, max(committed))

    def sell(self, sale: Sale) -> None:
        """The auctioneer's result: award the lot's tasks to the winner (in the order it drives
        them), log the round, send the winner its queue."""
        lot, best = sale.lot, sale.best
        driven = lot.driven(best.reverse)
        order = [tid for tid, _ in driven]
        for tid, reverse in driven:
            self.job.award(tid, best.robot, reverse)
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

    def _regions(self) -> tuple[bool, Callable[[], tuple[auction.Lot, ...]]]:
        """Whether this is the first allocation, and how the regions sold are cut
        (:func:`region_lots`): all tasks at first, and the work a lost robot leaves."""
        first = all(r.state == "open" for r in self.job.tasks.values())
        if first:
            self.region_sale = list(self.job.tasks)
        sale, self.region_sale = self.region_sale, []
        cut = region_lots(self.job, sale)
        return (first, cut) if self.parts is None else self.parts.regions(first, cut)

    def _bidders(self) -> list[str]:
        """The robots called to bid: those in the market."""
        return self.job.market()

    def _untried(self, lot: auction.Lot, robot: str) -> bool:
        """Whether ``robot`` may win ``lot``: untried by it (and as the parts allow)."""
        if any(robot in self.job.tasks[t].tried for t in lot.tasks):
            return False
        return self.parts is None or self.parts.may_win(lot, robot)

    def _settle(self) -> None:
        """Open tasks every robot in the market has tried are unreachable, and said so."""
        for tid in self.job.settle_unreachable():
            rec = self.job.tasks[tid]
            self.journal.event(
                "unreachable",
                "",
                tid,
                f"{rec.task.area_m2:.2f} m² tried by {', '.join(sorted(rec.tried))}: no robot "
                "gets it swept",
            )
            self.journal.save_tasks(tid)

    def _lots(self, regions: tuple[auction.Lot, ...]) -> dict[str, auction.Lot]:
        """What the next round sells: the regions none of whose tasks is sold yet, then every
        open task on its own (unless a part tells what)."""
        told = None if self.parts is None else self.parts.lots()
        if told is not None:
            return told
        open_ids = {r.task.id for r in self.job.open_tasks()}
        unsold = {lot.id: lot for lot in regions if set(lot.tasks) <= open_ids}
        if unsold:
            return unsold
        return {tid: auction.task_lot(self.job.tasks[tid].task) for tid in open_ids}

    # ---- the job's changes ----------------------------------------------------------------

    def swept(self, rid: str, msg: RobotStatus, plan: Plan | None) -> None:
        """Take the pieces ``rid`` reports swept of ``plan``, the plan it was last sent: a task
        of its chain all swept is done; one whose plan ended with pieces unswept is done, or
        given back as a remainder once."""
        if plan is None or msg.plan_id != plan.plan_id or self.job.robots[rid].liveness == LOST:
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
                held_up = not swept.all() and self.forgive(rid, plan.plan_id, tid)
                again = None if swept.all() else self.job.give_back(rid, tid, not held_up)
                if again is None:
                    self.job.finish(rid, tid)
                    self.journal.event("done", rid, tid, "")
                else:
                    peer = f" ({PEER_HELD}: not as tried by it)" if held_up else ""
                    self.journal.event(
                        "withdrawn", rid, tid, f"pieces given up: once more as {again}{peer}"
                    )
                    self.need_auction = True
                self.version += 1
                self.journal.save_tasks(*(t for t in (tid, again) if t is not None))
                self.wake.set()

    def lose(self, rid: str, why: str) -> None:
        """``rid`` is lost: its unswept remainder and unstarted tasks go on sale at once, as
        regions; it drives no plan."""
        queued = [r.task.id for r in self.job.queue(rid)]  # each saved in its new state
        reopened, made = self.job.lose(rid)
        self.version += 1
        self.journal.event("lost", rid, "", why)
        self.lost_at.update(dict.fromkeys(reopened, time.monotonic()))
        # a task may wait there still: sold meanwhile by an auction that was running when an
        # earlier loss put it there, and reopened now by this one
        self.region_sale += [t for t in reopened if t not in self.region_sale]
        for tid in reopened:
            self.journal.event("reopened", rid, tid, "remainder" if tid in made else "unstarted")
        self.journal.save_tasks(*queued, *reopened)
        self.dispatcher.forget(rid)
        self.progress.pop(rid, None)
        xy = self.job.robots[rid].xy
        if xy is not None:
            self.bodies[rid] = xy
            self.journal.event(
                "body", rid, "", f"its body stands at ({xy[0]:.2f}, {xy[1]:.2f}); planned around"
            )
            self.plan_around_bodies(rid)
        self.awards.send()
        self.need_auction = True
        self.wake.set()

    def rejoined(self, rid: str) -> None:
        """``rid`` is heard from again: its body is a robot again, so the work it blocked opens
        again, and so does the work no robot could reach (one more robot may)."""
        if self.bodies.pop(rid, None) is not None:
            self.dispatcher.planner.set_bodies(body_centres(self.bodies))
            self.journal.event("body", rid, "", "its robot is back: no longer planned around")
        reopened = self.job.reopen(rid)
        for tid in reopened:
            self.journal.event("reopened", rid, tid, "the way is free again")
        self.journal.save_tasks(*reopened)
        self.rebalance()

    def plan_around_bodies(self, body: str) -> None:
        """Take back every task whose path comes near a body (its owner's queue from there
        on), and replace it by what a robot can drive round the bodies and what they block."""
        planner = self.dispatcher.planner
        planner.set_bodies(body_centres(self.bodies))
        plan_around(self, planner.near_bodies, body, f"near {body}'s body", "round the body")

    # ---- progress ---------------------------------------------------------------------------

    def observe(self, rid: str, msg: RobotStatus) -> None:
        """Take a status report for the stall watch: waypoints reached on its plan, and how
        near (by its last pose) it is to the one it heads for. A waypoint given up is no
        progress: the robot heads for the next one from where it stands."""
        now = self.journal.clock
        reached = msg.waypoint - msg.skipped
        plan, xy = self.dispatcher.plans.get(rid), self.job.robots[rid].xy
        if plan is None or plan.plan_id != msg.plan_id or xy is None or not len(plan.waypoints):
            self.progress.pop(rid, None)
            return
        target = plan.waypoints[min(max(msg.waypoint, 0), len(plan.waypoints) - 1)]
        gap = math.dist(xy, target)
        near = 2 * self.dispatcher.planner.robot.radius + PEER_NEAR_GAP_M
        if any(
            o != rid and r.liveness != LOST and r.xy is not None and math.dist(xy, r.xy) < near
            for o, r in self.job.robots.items()
        ):
            self.met[rid] = msg.plan_id
        p = self.progress.get(rid)
        fresh = p is None or p.plan_id != msg.plan_id or msg.state in WAITING_STATES
        if fresh or reached > p.reached or gap < p.best_m - self.stall_progress_m:
            self.progress[rid] = Progress(msg.plan_id, reached, msg.waypoint, gap, now)
        elif msg.waypoint != p.heading_for:
            p.heading_for, p.best_m = msg.waypoint, gap

    def check_stalls(self) -> None:
        """Robots with work that have made no progress on their plans for ``stall_s``: stuck."""
        now = self.journal.clock
        for rid, p in list(self.progress.items()):
            r = self.job.robots.get(rid)
            plan = self.dispatcher.plans.get(rid)
            if r is None or r.liveness == LOST or self.job.current(rid) is None:
                continue
            if plan is None or plan.plan_id != p.plan_id or now - p.since < self.stall_s:
                continue
            held_up = self.forgive(rid, plan.plan_id, self.job.current(rid).task.id)
            self.stuck(rid, f"no progress on its plan for {now - p.since:.0f} s", held_up)

    def forgive(self, rid: str, plan_id: int, task_id: str) -> bool:
        """Put ``rid``'s trouble on ``task_id``, driven under plan ``plan_id``, down to a peer
        that came near it on that plan, and say whether it was: once per robot and task (its
        remainders included; the forgiveness is recorded), so two robots that keep meeting
        there end the way one alone does."""
        key = (rid, task_id.partition(".")[0])
        if self.met.get(rid) != plan_id or key in self.forgiven:
            return False
        self.forgiven.add(key)
        return True

    def stuck(self, rid: str, why: str, held_up: bool = False) -> None:
        """``rid`` is alive but gets nowhere: its work goes back to the market (what it was
        driving as tried by it, unless a peer ``held_up`` it), and it waits for other work,
        planned from where it stands."""
        queued = [r.task.id for r in self.job.queue(rid)]  # each saved in its new state
        reopened = self.job.release(rid, tried=not held_up)
        peer = f"; {PEER_HELD}, so not as tried by it" if held_up else ""
        self.journal.event("stuck", rid, "", f"{why}; its work goes back to the market{peer}")
        for tid in reopened:
            self.journal.event("reopened", rid, tid, "from a stuck robot")
        self.journal.save_tasks(*queued, *reopened)
        self.dispatcher.forget(rid)
        self.progress.pop(rid, None)
        self.version += 1
        self.awards.send()
        self.need_auction = True
        self.wake.set()

    def cannot_reach(self, rid: str, task_id: str, why: str) -> None:
        """No transit takes ``rid`` to ``task_id``: it gives its work back as a stuck robot
        does, and never wins that task again."""
        self.journal.event("unreachable", rid, task_id, why)
        self.stuck(rid, f"no way to {task_id}")

    def serve_idle(self) -> bool:
        """Rebalance (once per change of who works) when a robot in the market has no work while
        others hold queued tasks; whether an auction is due (open work untried by an idle robot)."""
        idle = [rid for rid in self.job.market() if self.job.current(rid) is None]
        queued = any(len(self.job.queue(rid)) > 1 for rid in self.job.robots)
        if idle and queued and self.version != self.balanced_version:
            self.rebalance()
        return any(rid not in rec.tried for rid in idle for rec in self.job.open_tasks())

    def rebalance(self) -> None:
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


def plan_around(
    market: Market,
    near: Callable[[np.ndarray], bool],
    cause: str,
    withdrawn: str,
    rerouted: str,
    reroute: Callable[[np.ndarray], Rerouted] | None = None,
) -> None:
    """Take back every task whose path is ``near`` what the planner now plans round (a
    body, new furniture; its owner's queue from there on), and replace it by what a robot
    can drive round that and the floor it puts out of reach (``blocked`` by ``cause``).
    ``withdrawn`` and ``rerouted`` say why in the events; ``reroute`` is the planner's, or
    the caller's when it has rerouted paths already. Called with the market's lock held."""
    planner = market.dispatcher.planner
    reroute = reroute or planner.reroute
    near_ids = [
        rec.task.id
        for rec in market.job.tasks.values()
        if rec.state in (OPEN, ASSIGNED) and near(rec.task.path)
    ]
    taken: list[str] = []  # what was taken back (saved: open, replaced or done) and opened
    for tid in near_ids:
        rec = market.job.tasks[tid]
        if rec.state != ASSIGNED or rec.owner is None:
            continue
        gone = [r.task.id for r in market.job.queue(rec.owner) if r.position >= rec.position]
        for later in gone:
            market.journal.event("withdrawn", rec.owner, later, withdrawn)
        taken += gone + market.job.take_back(tid)
    market.dispatcher.cut(taken)
    opened = [t for t in dict.fromkeys([*near_ids, *taken]) if market.job.tasks[t].state == OPEN]
    for tid in opened:
        rec = market.job.tasks[tid]
        if not near(rec.task.path):
            continue
        way = reroute(rec.task.path)
        if not way.changed:
            continue
        # a stretch a robot cannot drive whose floor some robot still sweeps from beside
        # it is no loss; the rest is floor put out of reach
        lost = [(p, a) for p in way.dropped if (a := planner.blocked_m2(p)) > 0]
        parts, blocked = market.job.replace(tid, way.paths, lost, cause)
        area = sum(market.job.tasks[t].task.area_m2 for t in blocked)
        market.journal.event(
            "rerouted",
            cause,
            tid,
            f"{rerouted}: {len(parts)} part(s) {' '.join(parts)}, {area:.2f} m² blocked",
        )
        market.journal.save_tasks(tid, *parts, *blocked)
        if (lost_at := market.lost_at.pop(tid, None)) is not None:
            market.lost_at.update(dict.fromkeys(parts, lost_at))
        if tid in market.region_sale:
            at = market.region_sale.index(tid)
            market.region_sale[at : at + 1] = parts
    market.journal.save_tasks(*taken)
    market.version += 1


def body_centres(bodies: Mapping[str, tuple[float, float]]) -> np.ndarray:
    return np.array(list(bodies.values()), dtype=float).reshape(-1, 2)


def estimate(journal: Journal, makespan_s: float) -> None:
    """The job's makespan as the first allocation prices it: the longest of the winners'
    committed times (travel from where each stood, and the cleaning time of what it won)."""
    log.info("the first allocation's makespan estimate: %.1f s", makespan_s)
    journal.event("estimated", "", "", f"makespan {makespan_s:.1f} s")
    journal.set_meta(estimate_s=round(makespan_s, 2))


def changed(job: Job, lots: Mapping[str, auction.Lot]) -> bool:
    """Whether a task of ``lots`` is no longer open: the job changed while they were called (a
    robot lost, its body planned round), and selling them would award a task that is gone."""
    open_ids = {r.task.id for r in job.open_tasks()}
    gone = [lot.id for lot in lots.values() if not set(lot.tasks) <= open_ids]
    if gone:
        log.info("lots %s changed while they were called; calling again", " ".join(gone))
    return bool(gone)


def await_ack(lock: threading.RLock, job: Job, rid: str, timeout_s: float) -> None:
    """Wait (``timeout_s`` at most) until ``rid`` has acknowledged the award of the lot it just
    won, or has left the market: a robot that bids in the next round before its award reaches
    it prices that round without what it won, and wins lots it cannot do in time."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with lock:
            r = job.robots.get(rid)
            if r is None or r.acked_seq >= r.award_seq or rid not in job.market():
                return
        time.sleep(ACK_POLL_S)


def region_lots(job: Job, sale: list[str]) -> Callable[[], tuple[auction.Lot, ...]]:
    """The open tasks of ``sale`` as regions, one per robot in the market: runs of the tour
    (``planners.auction.regions``); none without robots. Read from the job now, cut when
    called (outside the market's lock)."""
    bidders = job.market()
    open_ = (t for t in sale if job.tasks[t].state == OPEN)
    runs = sorted((job.tasks[t].task for t in open_), key=_tour_key)
    if not bidders:
        return lambda: ()
    return lambda: auction.regions(runs, len(bidders))


def _tour_key(task: auction.Task) -> tuple[int, ...]:
    """Where a task lies along the tour: "t07" → (7,), its remainder "t07.1" → (7, 1)."""
    return tuple(int(n) for n in re.findall(r"\d+", task.id))
