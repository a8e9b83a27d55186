"""Docks and the trips to them: which robot charges where, who waits, and when each works again.

With batteries (``robot.battery``) a robot whose charge falls below ``recharge_threshold``, or
that can do none of the open work on its charge, is sent to charge: the work it holds is taken
back (the unswept remainder of the task it drives and its unstarted tasks go back to the market,
as a lost robot's do, none of them counted as tried by it), and it gets a plan to a dock, driven
like any plan: the transit (A* on the floor plan) to a point in front of the dock, then straight
onto it, so it arrives facing the dock as the dock needs. A dock holds one robot: a robot going
to charge takes the dock its charge covers that it is on soonest, its trip and its wait behind the
robots ahead there counted (``planners.battery.pick_dock``); when that dock is held it waits at a
waiting spot by it (free floor near it, clear of its approach), in the order the robots came, and
goes on once the dock is free. At the job's end a robot parks at the nearest dock no robot holds,
else waits by the nearest. A robot that makes no progress on its trip for the stall time gets it
planned again from where it stands, then another dock or waiting spot
(:meth:`Docking.stalled`). A dock with a body on it or on the line onto it (a lost robot's, or
one whose battery ran out) is not used; a robot with no dock left works until it runs out. The
charge below which a robot is sent counts its trip and the queue ahead of it at that dock, the
robots at work that fall due with or before it included (:meth:`Docking.go_home_below`). On the
dock it charges until ``recharge_to`` and is back in the market. At the end of the job every
robot is sent home, and the job is finished once each is on a dock or at its waiting spot.

What the coordinator knows of a battery is what the robot's status says (its charge, whether a
dock charges it), and nothing from the simulator.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fleet.coordinator import go_home
from fleet.coordinator.dispatcher import Dispatcher, Errand
from fleet.coordinator.job import EMPTY, LOST
from fleet.coordinator.journal import Journal
from fleet.coordinator.planning import TaskPlanner
from fleet.protocol import Plan, RobotStatus
from planners.battery import BatterySpec, DockUser, pick_dock
from planners.grid import GridMap, clearance

# the names of errand plans (their kind says what they are): dock-0, dock-1, ... onto a dock;
# wait-0, ... to the waiting spot by a taken dock
DOCK_PREFIX = "dock-"
WAIT_PREFIX = "wait-"

log = logging.getLogger("coordinator")

Pose = tuple[float, float, float]
# a robot drives onto its dock straight from this far in front of it (m), and stops this far in
# front of the dock's pose (within the dock's tolerance): closer, DWA creeps and turns by the
# dock's body and the robot ends up skewed on it
APPROACH_M = 0.35
STOP_SHORT_M = 0.04
# waiting spots keep this far from a dock's pose and from each other (m), and this far from the
# line a robot drives onto the dock by
SPOT_FROM_DOCK_M = 0.7
SPOT_SPACING_M = 0.55
SPOT_FROM_APPROACH_M = 0.45
# a robot at the end of a dock plan that does not charge within this (sim s) is sent again
DOCKING_GRACE_S = 5.0
DOCKING_TRIES = 3
# a robot whose statuses do not show it driving its dock plan gets it again after this (wall s)
RESEND_S = 2.0
# a robot standing this near a dock's pose holds it, trip or not (m)
HOLDS_M = 0.3


@dataclass
class Trip:
    """A robot's way home: to ``dock`` (its index) or, ``waiting``, to a spot by it; ``plan``
    the plan sent; ``parking``: the job is over; ``tries`` of docking so far, ``stalls``: how
    often it has stood still on its way, ``sent_wall`` when the plan last went out (wall s),
    ``ended`` when it was first seen at the plan's end (sim s); ``clearing``: a charged robot
    sent off the dock to a spot, back in the market once there."""

    dock: int
    waiting: bool
    plan: Plan
    parking: bool
    tries: int = 1
    stalls: int = 0
    sent_wall: float = 0.0
    ended: float | None = None
    clearing: bool = False


class Docking:
    """The docks, their waiting spots and the robots' trips to them (called with the lock)."""

    def __init__(
        self,
        journal: Journal,
        planner: TaskPlanner,
        dispatcher: Dispatcher,
        spec: BatterySpec,
        docks: tuple[Pose, ...],
    ) -> None:
        self.journal = journal
        self.job = journal.job
        self.planner = planner
        self.dispatcher = dispatcher
        self.spec = spec
        self.docks = docks
        self.trips: dict[str, Trip] = {}
        self._floor: GridMap | None = None
        self._follow_floor()
        dispatcher.on_errand = self._replanned

    def _follow_floor(self) -> None:
        """The waiting spots and the travel times on the floor the planner plans on now: an
        exploring fleet's merged map grows at every update, a stored map takes the furniture
        found moved."""
        if self.planner.grid is self._floor:
            return
        self._floor = self.planner.grid
        self.spots = [waiting_spots(self.planner, d, self.docks) for d in self.docks]
        self.travel = self.planner.travel()

    # ---- who holds what ---------------------------------------------------------------------

    def holder(self, k: int) -> str | None:
        """The robot that holds dock ``k``: on a trip to it, or standing on it charging (just
        charged, before it drives off) or without work. A robot at work that passes over the
        dock's pose (lanes along the wall run over it) does not hold it."""
        for rid, t in self.trips.items():
            if t.dock == k and not t.waiting:
                return rid
        for rid, r in self.job.robots.items():
            free = r.liveness == LOST or r.xy is None or rid in self.trips
            if not free and self._on(k, r.xy) and (r.charging or not self.job.queue(rid)):
                return rid
        return None

    def _on(self, k: int, xy: tuple[float, float]) -> bool:
        return math.dist(xy, self.docks[k][:2]) < HOLDS_M

    def usable(self, k: int) -> bool:
        """Whether a robot can drive onto dock ``k``: no body (a lost robot's, or one out of
        charge) stands on it or on the line onto it."""
        dock = self.docks[k]
        return not self.planner.near_bodies(np.vstack([_approach(dock), dock[:2]]))

    def trip_to(self, k: int, xy: tuple[float, float]) -> float:
        """Travel time on the floor plan from ``xy`` to dock ``k`` (inf where there is no way):
        the dock in the next room may be nearer as the crow flies than this room's."""
        self._follow_floor()
        return float(self.travel(np.array(self.docks[k][:2]), np.array([xy]))[0])

    def _nearest(self, xy: tuple[float, float], free_only: bool) -> int | None:
        ks = [
            k
            for k in range(len(self.docks))
            if self.usable(k) and (not free_only or self.holder(k) is None)
        ]
        return min(ks, key=lambda k: self.trip_to(k, xy), default=None)

    def ahead(self, k: int) -> list[float]:
        """The charges of the robots ahead of a newcomer at dock ``k``: on their way to it,
        waiting by it or charging on it (parking at the job's end aside)."""
        robots = self.job.robots
        return [
            robots[rid].charge for rid, t in self.trips.items() if t.dock == k and not t.parking
        ]

    def go_home_below(self, rid: str) -> float:
        """The charge below which ``rid`` goes to charge now (0: no dock it can charge on; it
        works until it runs out): the threshold plus its trip to the dock it would take and its
        wait there behind the robots ahead of it, those at work that fall due with or before it
        included (:func:`fleet.coordinator.go_home.points`)."""
        found = go_home.points(self).get(rid)
        return found[1] if found is not None else go_home.alone(self, rid)[1]

    def dock_user(self, rid: str) -> tuple[int, DockUser] | None:
        """The dock ``rid`` would charge at and what the stagger rule needs of it
        (``planners.battery.charge_early``): its charge, its trip there and its seconds of
        work, at the sweeping drain, until it falls to its go-home point with the docks as they
        stand (the stagger rule orders the robots at work at a dock itself)."""
        k, below = go_home.alone(self, rid)
        r = self.job.robots[rid]
        if k is None or r.xy is None:
            return None
        trip_s = self.trip_to(k, r.xy)
        return k, DockUser(r.charge, trip_s, (r.charge - below) * self.spec.capacity_s)

    def free(self, k: int) -> bool:
        """Whether dock ``k`` is free now: usable, held by no robot, and nobody bound for it."""
        return (
            self.usable(k)
            and self.holder(k) is None
            and not any(t.dock == k for t in self.trips.values())
        )

    def trip_s(self, points: np.ndarray) -> float:
        """The mean travel time (s) between ``points`` ((N, 2)) and the dock nearest each, on
        the floor plan at the transit speed (0 with no dock reached)."""
        if not self.docks or not len(points):
            return 0.0
        self._follow_floor()
        each = np.min([self.travel(np.array(d[:2]), points) for d in self.docks], axis=0)
        each = each[np.isfinite(each)]
        return float(each.mean()) if len(each) else 0.0

    # ---- trips ------------------------------------------------------------------------------

    def send(self, rid: str, why: str, parking: bool, dock: int | None = None) -> bool:
        """Send ``rid`` (with no work) home; False when there is no way there. To charge: to
        the dock its charge covers that it is on soonest, counting the robots ahead there
        (``planners.battery.pick_dock``), to wait by it when it is held. To park at the job's
        end: to the nearest free dock, else to wait by the nearest. Given a ``dock`` (an
        operator's choice), to that one, to wait by it when it is held."""
        r = self.job.robots[rid]
        if r.xy is None or not self.docks:
            return False
        if dock is not None:
            k, waiting = dock, self.holder(dock) not in (None, rid)
        elif parking:
            k = self._nearest(r.xy, free_only=True)
            waiting = k is None
            if k is None:
                k = self._nearest(r.xy, free_only=False)
        else:
            ahead = [self.ahead(k) for k in range(len(self.docks))]
            k = pick_dock(self.spec, r.charge, go_home.trips_s(self, r.xy), ahead)
            waiting = k is not None and self.holder(k) is not None
        if k is None:
            return False
        r.docking = "waiting" if waiting else "docking"
        if not self._go(rid, k, waiting, parking):
            r.docking = ""
            return False
        where = f"to wait by dock {k}" if waiting else f"to dock {k}"
        self.journal.event("dock", rid, self.trips[rid].plan.task, f"{why}: {where}")
        return True

    def _go(
        self,
        rid: str,
        k: int,
        waiting: bool,
        parking: bool,
        tries: int = 1,
        stalls: int = 0,
        avoid: np.ndarray | None = None,
    ) -> bool:
        """Plan ``rid``'s trip from where it stands to dock ``k`` or, ``waiting``, to the
        first waiting spot by it no other robot is bound for (nor ``avoid``), and send it."""
        dock = self.docks[k]
        self._follow_floor()
        if waiting:
            taken = {
                t.plan.waypoints[-1].tobytes()
                for other, t in self.trips.items()
                if t.waiting and other != rid
            }
            if avoid is not None:
                taken.add(np.asarray(avoid, dtype=float).tobytes())
            spot = next(
                (s for s in self.spots[k] if np.array(s).tobytes() not in taken),
                self.spots[k][-1] if self.spots[k] else None,
            )
            if spot is None:
                return False
            errand = Errand(f"{WAIT_PREFIX}{k}", spot, kind="wait")
        else:
            front = _approach(dock)
            onto = _approach(dock, STOP_SHORT_M)[None]
            errand = Errand(f"{DOCK_PREFIX}{k}", (float(front[0]), float(front[1])), onto, "dock")
        try:
            plan = self.dispatcher.send_errand(rid, errand)
        except ValueError as e:
            self.journal.event("unreachable", rid, f"{DOCK_PREFIX}{k}", str(e))
            return False
        self.trips[rid] = Trip(k, waiting, plan, parking, tries, stalls, time.monotonic())
        return True

    def _replanned(self, rid: str, plan: Plan) -> None:
        """A round planned ``rid``'s errand again (:meth:`Dispatcher.send_errand`)."""
        t = self.trips.get(rid)
        if t is not None and plan.task == t.plan.task:
            t.plan = plan

    def heard(self, rid: str, msg: RobotStatus) -> None:
        r = self.job.robots[rid]
        r.charge, r.charging = msg.charge, msg.charging
        # a robot charges on any dock it stands on: passing over another on its way is not
        # being on its own
        t = self.trips.get(rid)
        on_its_dock = t is not None and r.xy is not None and self._on(t.dock, r.xy)
        if r.charging and on_its_dock and r.docking == "docking":
            r.docking = "charging"
            self.journal.event("charging", rid, self.trips[rid].plan.task, f"at {msg.charge:.2f}")
        elif t and r.docking == "charging" and not r.charging and r.charge < self.spec.recharge_to:
            # it stopped off the dock (pushed, or it only passed within the dock's tolerance):
            # docking again, as a robot at the end of its plan that does not charge
            r.docking = "docking"
            self.journal.event("dock", rid, t.plan.task, f"off the dock at {r.charge:.2f}")

    def tick(self, job_over: bool) -> list[str]:
        """Move the trips on: robots charged back to work (returned), waiting robots onto
        freed docks, a missed docking tried again, lost plans sent again."""
        back = []
        now = self.journal.clock
        _clear_docks(self)
        for rid, t in list(self.trips.items()):
            r = self.job.robots[rid]
            if r.liveness == LOST or (t.clearing and self._at_end(rid, t)):
                self._drop(rid)
                back += [rid] if t.clearing else []
                continue
            if t.clearing:
                self._resend(rid)
                continue
            if not self.usable(t.dock) and not r.charging:
                if self._blocked(rid, t):
                    back.append(rid)
                continue
            if r.docking == "charging" and r.charge >= self.spec.recharge_to and not job_over:
                self._drop(rid)
                self.journal.event("charged", rid, t.plan.task, f"at {r.charge:.2f}; bids again")
                back.append(rid)
            elif t.waiting and self.holder(t.dock) is None and self._may_go_on(rid, t):
                r.docking = "docking"
                self._go(rid, t.dock, False, t.parking, stalls=t.stalls)
            elif r.docking == "docking" and not r.charging and self._at_end(rid, t):
                self._missed(rid, t, now)
            self._resend(rid)
        return back

    def _may_go_on(self, rid: str, t: Trip) -> bool:
        """A robot sent to wait because it stood still on its way goes on to the dock from its
        waiting spot, not straight back along the way it stood still on."""
        return not t.stalls or self._at_end(rid, t)

    def stalled(self, rid: str, why: str) -> None:
        """``rid`` has made no progress on its trip for the stall time (in a doorway, face to
        face with a robot at work, say). The first time, its trip is planned again from where
        it stands (round the bodies); after that it is sent to the nearest other dock no robot
        holds, else to another waiting spot, so the way it stood still on is not the only one
        it tries."""
        t = self.trips[rid]
        r = self.job.robots[rid]
        if r.xy is None:
            return
        stalls = t.stalls + 1
        if stalls == 1:
            self.journal.event("dock", rid, t.plan.task, f"{why}: planned again from where it is")
            self._go(rid, t.dock, t.waiting, t.parking, t.tries, stalls)
            return
        others = [
            k
            for k in range(len(self.docks))
            if k != t.dock and self.usable(k) and self.holder(k) is None
        ]
        if others:
            k = min(others, key=lambda k: self.trip_to(k, r.xy))
            r.docking = "docking"
            sent = self._go(rid, k, False, t.parking, 1, stalls)
            where = f"to dock {k}"
        else:
            r.docking = "waiting"
            avoid = t.plan.waypoints[-1] if t.waiting else None
            sent = self._go(rid, t.dock, True, t.parking, 1, stalls, avoid)
            where = (
                f"to another spot by dock {t.dock}" if t.waiting else f"to wait by dock {t.dock}"
            )
        if sent:
            self.journal.event("dock", rid, self.trips[rid].plan.task, f"{why}: {where}")

    def _blocked(self, rid: str, t: Trip) -> bool:
        """A body now stands on ``rid``'s dock or on the line onto it: it goes on to the
        nearest other dock it can use; with none, it is back in the market (True) and works
        until it runs out."""
        self._drop(rid)
        self.journal.event("dock", rid, t.plan.task, f"dock {t.dock} is blocked by a body")
        if self.send(rid, "its dock is blocked", t.parking):
            return False
        self.journal.event("dock", rid, "", "no dock it can charge on: back to work")
        return True

    def _missed(self, rid: str, t: Trip, now: float) -> None:
        """``rid`` is at the end of its dock plan but does not charge: once that has lasted
        ``DOCKING_GRACE_S``, it drives onto the dock again (``DOCKING_TRIES`` in all)."""
        if t.ended is None:
            t.ended = now
        elif now - t.ended > DOCKING_GRACE_S and t.tries < DOCKING_TRIES:
            self.journal.event("dock", rid, t.plan.task, "not on the dock; trying again")
            self._go(rid, t.dock, False, t.parking, t.tries + 1)

    def _at_end(self, rid: str, t: Trip) -> bool:
        at = self.dispatcher.progress_of.get(rid)
        return at is not None and at[0] == t.plan.plan_id and at[1] >= len(t.plan.waypoints)

    def _resend(self, rid: str) -> None:
        t = self.trips.get(rid)
        if t is None:
            return
        at = self.dispatcher.progress_of.get(rid)
        now = time.monotonic()
        if (at is None or at[0] != t.plan.plan_id) and now - t.sent_wall > RESEND_S:
            t.sent_wall = now
            d = self.dispatcher
            d.publish(d.keys.plan(rid), t.plan, True)

    def _drop(self, rid: str) -> None:
        self.trips.pop(rid, None)
        self.job.robots[rid].docking = ""
        self.dispatcher.forget(rid)

    def empty(self, rid: str) -> None:
        """``rid``'s battery ran out away from a dock: it stands for good, holds no dock and
        counts as home (its work taken back, its body planned round:
        ``ChargingPart.run_flat``)."""
        t = self.trips.get(rid)
        self._drop(rid)
        self.job.robots[rid].docking = EMPTY
        self.journal.event("empty", rid, t.plan.task if t else "", "its battery ran out")

    def home(self) -> bool:
        """Whether every robot not lost is home: charging, or at the end of its trip (or
        standing for good with an empty battery)."""
        for rid, r in self.job.robots.items():
            if r.liveness == LOST or r.docking == EMPTY:
                continue
            t = self.trips.get(rid)
            if t is None or not (r.charging or self._at_end(rid, t)):
                return False
        return True


def _clear_docks(docking: Docking) -> None:
    """A robot charged to ``recharge_to`` and without work that stands on a dock a robot waits
    by (at its spot) holds it until it wins work, while the waiting robot runs down; and it does
    not step aside (the waiting one's path stops short of it). It is sent to a waiting spot by
    that dock, out of the market until it is there."""
    job = docking.job
    for k in range(len(docking.docks)):
        rid = docking.holder(k)
        if rid is None or rid in docking.trips or job.queue(rid):
            continue
        r = job.robots[rid]
        waited = any(
            t.dock == k and t.waiting and docking._at_end(other, t)
            for other, t in docking.trips.items()
        )
        if not waited or r.charge < docking.spec.recharge_to:
            continue
        r.docking = "waiting"
        if docking._go(rid, k, True, False):
            docking.trips[rid].clearing = True
            docking.journal.event("dock", rid, f"{WAIT_PREFIX}{k}", "charged: clears the dock")
        else:
            r.docking = ""


def waiting_spots(
    planner: TaskPlanner, dock: Pose, docks: Sequence[Pose], n: int = 8
) -> list[tuple[float, float]]:
    """Up to ``n`` waiting spots by ``dock``, nearest first: floor a robot reaches on
    ``planner``'s floor plan, clear of obstacles, of every dock of ``docks`` and of the line
    onto ``dock``."""
    g = planner.grid
    ok = planner.reachable & (clearance(g) >= planner.centre_clearance + 0.05)
    pts = g.cell_to_world(np.argwhere(ok))
    front = _approach(dock)
    d_dock = np.hypot(*(pts - np.array(dock[:2])).T)
    d_line = _to_segment(pts, np.array(dock[:2]), front)
    keep = (d_dock >= SPOT_FROM_DOCK_M) & (d_line >= SPOT_FROM_APPROACH_M)
    for other in docks:
        keep &= np.hypot(*(pts - np.array(other[:2])).T) >= SPOT_FROM_DOCK_M
    order = np.argsort(np.hypot(*(pts - front).T) + 1e9 * ~keep, kind="stable")
    out: list[tuple[float, float]] = []
    for p in pts[order[: int(keep.sum())]]:
        if all(math.dist(p, q) >= SPOT_SPACING_M for q in out):
            out.append((float(p[0]), float(p[1])))
            if len(out) == n:
                break
    return out


def _approach(dock: Pose, ahead: float = APPROACH_M) -> np.ndarray:
    """The point ``ahead`` m in front of ``dock`` (by default where a robot drives straight on
    from)."""
    return np.array([dock[0] + ahead * math.cos(dock[2]), dock[1] + ahead * math.sin(dock[2])])


def _to_segment(pts: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.clip(((pts - a) @ ab) / max(float(ab @ ab), 1e-12), 0.0, 1.0)
    return np.hypot(*(pts - (a + t[:, None] * ab)).T)
