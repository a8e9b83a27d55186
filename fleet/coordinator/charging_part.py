"""Batteries (``robot.battery.enabled``), a part of the coordinator: the job and the market as
without them, and the robots' trips to charge (:mod:`fleet.coordinator.charging`). It composes
with the others: exploring, it sends robots to charge on the merged map as it grows.

- It serves the world's docks on ``coord/docks``: robots price the way home from each task.
- A robot whose status reports a charge below ``recharge_threshold`` plus what its trip to a
  dock and the queue ahead of it there cost (:meth:`Docking.go_home_below`) is taken out of
  the market and sent to a dock; the work it held goes back to the market.
- Charges are staggered: while a dock is free and nobody is bound for it, the robot at work
  that falls due first there is sent early when waiting longer would put its charge in the
  way of the next robot's (``planners.battery.charge_early``, :func:`charging_early`).
- An auction that sells nothing while work is open (every robot declined it on its charge)
  sends the idle robots that are not charged to ``recharge_to`` to charge.
- The first allocation sells regions, one per robot, only when each robot's charge covers a
  region's work; otherwise task by task, so a robot takes what its charge allows.
- A robot whose battery runs out off a dock stands for good: its work goes back to the market
  and its body is planned round like a lost robot's (a dock it blocks is not used). When no
  robot can work any more, the open work is left out (event ``stranded``) and the job ends
  ``incomplete``.
- The job's estimate (``plan_estimate_s``) counts the charges: the first allocation's regions
  worked from each robot's charge, the trips to a dock and back (each region's mean travel to
  its nearest dock on the floor plan), queueing at the docks for the charges they need, and
  the trip home at the end.
- When the job's work is over (``Coordinator.work_over``: every task done, or exploring, no
  frontier left), every robot is sent home; the job ends once each is on a dock or at its
  waiting spot.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np

from fleet.coordinator import go_home
from fleet.coordinator.charging import Docking, Pose
from fleet.coordinator.job import ASSIGNED, EMPTY, LOST, OPEN, Job, TaskRecord
from fleet.coordinator.market import Cut, estimate
from fleet.coordinator.parts import Host, Part
from fleet.protocol import Docks, OpsReply, OpsRequest, Request, RobotStatus
from planners import auction
from planners.battery import BatterySpec, DockUser, can_take, charge_early, makespan_with_charging

log = logging.getLogger("coordinator")


class ChargingPart(Part):
    """The robots' trips to charge: out of the market and back, the docks served, the job's
    end held until every robot is home."""

    docking: Docking
    # the first allocation's regions, one per robot: each one's work (s) and its mean trip to a
    # dock (s)
    first_regions: tuple[tuple[float, float], ...] = ()

    def __init__(self, battery: BatterySpec, docks: tuple[Pose, ...]) -> None:
        self.battery = battery
        self.docks = docks

    def wire(self, host: Host) -> None:
        """The docks and the trips to them, before the first status is heard (a status handled
        without them was dropped with an error at the start of a run)."""
        self.host = host
        self.job, self.journal, self.market = host.job, host.journal, host.market
        self.docking = Docking(
            host.journal, host.planner, host.dispatcher, self.battery, self.docks
        )

    def serve(self) -> None:
        bus, keys = self.host.bus, self.host.keys
        poses = np.array(self.docks, dtype=float).reshape(-1, 3)
        bus.serve(keys.docks(), Request, lambda _req: Docks(self.journal.clock, poses))
        bus.serve(keys.ops("dock"), OpsRequest, self._on_dock)

    # ---- the market's hooks -----------------------------------------------------------------

    def after_auction(self, sold: int) -> None:
        """When an auction sold nothing while work is open, the idle robots it could not
        interest (they declined on their charge) and that are not full go to charge."""
        if sold or not self.job.open_tasks():
            return
        for rid in self.job.market():
            r = self.job.robots[rid]
            idle = self.job.current(rid) is None and 0 <= r.charge < self.battery.recharge_to
            if idle and self.docking.go_home_below(rid) > 0:  # a dock it can charge on
                self.send_home(rid, f"can do none of the open work on {r.charge:.2f}")

    def regions(self, first: bool, cut: Cut) -> tuple[bool, Cut]:
        """The market's regions, none unless every robot's charge covers the longest."""
        charges = [self.job.robots[rid].charge for rid in self.job.market()]
        reach_s = min(charges, default=1.0) * self.battery.capacity_s

        def within_charge() -> tuple[auction.Lot, ...]:
            regions = cut()
            if first:
                self.first_regions = tuple((lot.time_s, self._trip_s(lot)) for lot in regions)
            return () if any(lot.time_s > reach_s for lot in regions) else regions

        return first, within_charge

    def _trip_s(self, lot: auction.Lot) -> float:
        """A region's trip to a dock: the mean, over where its tasks start, of the travel to
        the nearest dock (a robot goes to charge from somewhere in its region)."""
        starts = [self.job.tasks[tid].task.path[0] for tid in lot.tasks if tid in self.job.tasks]
        return self.docking.trip_s(np.array(starts, dtype=float).reshape(-1, 2))

    def estimate_first(self, committed: list[float]) -> bool:
        """The job's estimate with the charges in it, whether or not the first allocation sold
        everything (robots decline what their charge cannot cover): the first allocation's
        regions, one per robot, each worked from its robot's charge with the trips to a dock
        and back and the charges it needs at the docks in turn, and the trip home at the end
        (``planners.battery.makespan_with_charging``); not without one region per robot."""
        regions = sorted(self.first_regions, key=lambda r: -r[0])
        market = self.job.market()
        if not regions or len(regions) != len(market):
            return False
        charges = sorted((self._charge(rid) for rid in market), reverse=True)
        work = [w for w, _ in regions]
        trips = [t for _, t in regions]
        docks = len(self.docking.docks)
        estimate(self.journal, makespan_with_charging(self.battery, work, charges, docks, trips))
        return True

    def _charge(self, rid: str) -> float:
        charge = self.job.robots[rid].charge
        return 1.0 if charge < 0 else charge

    # ---- the service's hooks ----------------------------------------------------------------

    def check_stalls(self) -> None:
        """Robots on a trip to a dock or a waiting spot that have made no progress on it for
        ``stall_s`` (:meth:`Docking.stalled`; robots with work are the market's)."""
        now = self.journal.clock
        progress = self.market.progress
        for rid, p in list(progress.items()):
            t = self.docking.trips.get(rid)
            if t is None or self.job.robots[rid].charging or t.plan.plan_id != p.plan_id:
                continue
            if now - p.since >= self.market.stall_s:
                progress.pop(rid)
                self.docking.stalled(rid, f"no progress on its trip for {now - p.since:.0f} s")

    def observe(self, rid: str, msg: RobotStatus) -> None:
        self.docking.heard(rid, msg)

    def tick(self) -> None:
        """Trips on; robots below the threshold to charge; once the work is over, all home."""
        over = self.host.work_over()
        if self.docking.tick(over):
            self.market.need_auction = True
        for rid, why, parking in homeward(self.job, self.docking, over):
            self.send_home(rid, why, parking)
        for rid, why in charging_early(self.job, self.docking, over):
            self.send_home(rid, why)
        self.check_flat()

    def settled(self) -> bool:
        """Every robot not lost is home (on a dock, at its waiting spot, or out of charge)."""
        return self.docking.home()

    def _on_dock(self, req: OpsRequest) -> OpsReply:
        """`fleet dock ROBOT [--dock K]`: send it home now (to dock K)."""
        with self.host.lock:
            r = self.job.robots.get(req.name)
            if req.verb != "dock" or r is None:
                return OpsReply(False, f"no robot {req.name!r} in the job")
            if r.liveness == LOST or r.xy is None:
                return OpsReply(False, f"{req.name} is lost, or has not said where it is")
            dock = None if req.dock < 0 else req.dock
            if dock is not None and dock >= len(self.docks):
                count = f"{len(self.docks)} dock{'s' if len(self.docks) != 1 else ''}"
                return OpsReply(False, f"no dock {dock}: the world has {count}, from 0")
            if dock is not None and not self.docking.usable(dock):
                return OpsReply(False, f"dock {dock} cannot be reached: a body stands on it")
            if r.docking:
                trip = self.docking.trips.get(req.name)
                if dock is None or trip is None or trip.dock == dock:
                    return OpsReply(True, "")
                return OpsReply(False, f"{req.name} is already bound for dock {trip.dock}")
            why = f"sent home by {req.sender}"
            self.send_home(req.name, why, parking=self.host.work_over(), dock=dock)
            ok = bool(r.docking)
        return OpsReply(ok, "" if ok else f"no way home for {req.name}")

    # ---- the job's changes ------------------------------------------------------------------

    def send_home(self, rid: str, why: str, parking: bool = False, dock: int | None = None) -> None:
        """Take ``rid``'s work back (the unswept remainder of the task it drives and its
        unstarted tasks go back to the market, not as tried by it) and send it home: to dock
        number ``dock`` if given, else to the one :meth:`Docking.send` picks."""
        self._take_back(rid, "its robot went to charge")
        if not self.docking.send(rid, why, parking, dock):
            log.warning("%s: no way home (%s)", rid, why)
        self.market.wake.set()

    def run_flat(self, rid: str) -> None:
        """``rid``'s battery ran out off a dock: it stands for good. Its work goes back to the
        market, and its body is planned round as a lost robot's is (tasks near it re-cut,
        transits round it, a dock it blocks not used)."""
        self._take_back(rid, "its robot ran out of charge")
        self.docking.empty(rid)
        xy = self.job.robots[rid].xy
        market = self.market
        if xy is not None:
            market.bodies[rid] = xy
            where = f"({xy[0]:.2f}, {xy[1]:.2f})"
            self.journal.event("body", rid, "", f"out of charge at {where}; planned around")
            market.plan_around_bodies(rid)
        market.need_auction = True
        market.wake.set()

    def check_flat(self) -> None:
        """Robots whose status reports 0 % off a dock stand for good (:meth:`run_flat`); when
        no robot can work any more (each lost or out of charge, one at least out of charge)
        while work is open, the open work is left out and the job ends ``incomplete`` rather
        than wait for robots that will not come."""
        for rid, r in self.job.robots.items():
            if r.charge == 0.0 and not r.charging and r.docking != EMPTY and r.liveness != LOST:
                self.run_flat(rid)
        robots = self.job.robots.values()
        if self.job.bidders() or not any(r.docking == EMPTY for r in robots):
            return
        left = self.job.strand()
        if left:
            self.journal.event(
                "stranded", "", "", f"no robot can work any more: {len(left)} task(s) left open"
            )
            self.journal.save_tasks(*left)

    def _take_back(self, rid: str, why: str) -> None:
        market = self.market
        queue = [rec.task.id for rec in self.job.queue(rid)]
        opened = self.job.take_back(queue[0]) if queue else []
        for tid in opened:
            self.journal.event("reopened", rid, tid, why)
        self.journal.save_tasks(*queue, *opened)
        market.dispatcher.forget(rid)
        market.progress.pop(rid, None)
        market.version += 1
        market.awards.send()
        market.need_auction = market.need_auction or bool(opened)


def going_home(job: Job, below: Callable[[str], float], over: bool) -> list[tuple[str, str, bool]]:
    """The robots to send home now, each with why and whether to park: once the job's work is
    ``over``, every robot not yet on its way home; before, each robot in the market whose
    charge has fallen below what it needs to get to a dock and wait there (``below(robot)``)."""
    out = []
    for rid, r in sorted(job.robots.items()):
        if r.liveness == LOST or r.docking or r.xy is None:
            continue
        if over:
            out.append((rid, "the job is done", True))
        elif r.in_market and r.charge >= 0 and r.charge < (need := below(rid)):
            out.append((rid, f"charge {r.charge:.3f} below {need:.3f}", False))
    return out


def homeward(job: Job, docking: Docking, over: bool) -> list[tuple[str, str, bool]]:
    """:func:`going_home` in the order to send them: once the work is ``over`` so that each
    free dock goes to the robot nearest it (``go_home.nearest_first``); before, in the order
    they fall due, the order their go-home points were counted in (``go_home.points``), so
    each robot finds the docks as its go-home point counted them."""
    points = go_home.points(docking)

    def below(rid: str) -> float:
        return points[rid][1] if rid in points else go_home.alone(docking, rid)[1]

    home = {rid: (why, parking) for rid, why, parking in going_home(job, below, over)}
    if over:
        order = go_home.nearest_first(docking, list(home))
    else:
        order = [rid for rid in points if rid in home] + [r for r in home if r not in points]
    return [(rid, *home[rid]) for rid in order]


def charging_early(job: Job, docking: Docking, over: bool) -> list[tuple[str, str]]:
    """The robots to send to charge before their go-home point, each with why: per free dock,
    the one the stagger rule picks (``planners.battery.charge_early``) among the robots at
    work that would charge there and need to before the job ends (their charge does not cover
    the work they hold, nor their share of the work left, and the trip home). None once the
    job's work is ``over``."""
    if over:
        return []
    left = [rec for rec in job.tasks.values() if rec.state in (OPEN, ASSIGNED)]
    working = [r for r in job.robots.values() if r.liveness != LOST and r.docking != EMPTY]
    share_s = sum(_left_s(rec) for rec in left) / max(len(working), 1)
    users: dict[int, list[tuple[str, DockUser]]] = {}
    for rid, r in sorted(job.robots.items()):
        if not r.in_market or r.charge < 0:
            continue
        found = docking.dock_user(rid)
        if found is None:
            continue
        k, user = found
        need_s = max(sum(_left_s(rec) for rec in job.queue(rid)), share_s)
        if not can_take(docking.spec, user.charge, need_s, user.trip_s):
            users.setdefault(k, []).append((rid, user))
    out = []
    for k, group in sorted(users.items()):
        if not docking.free(k):
            continue
        pick = charge_early(docking.spec, [user for _, user in group])
        if pick is not None:
            rid, user = group[pick]
            out.append((rid, f"charge {user.charge:.3f}, dock {k} free: charging early"))
    return out


def _left_s(rec: TaskRecord) -> float:
    """The work (s) left of a task: its time less the share of its pieces swept."""
    swept = float(rec.swept.mean()) if rec.swept.size else 0.0
    return rec.task.time_s * (1.0 - swept)
