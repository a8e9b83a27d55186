"""The dispatcher: each robot's plan, and the transits between tasks.

A robot gets a plan once it has acknowledged the award of its current task: the transit from
its reported pose to that task, then the task's sweep and those of the queued tasks that follow
on without a transit (:mod:`fleet.plan_chain`), as one plan on ``coord/plan/<robot>``
(:meth:`fleet.coordinator.planning.TaskPlanner.drive`), so a robot drives its region without
stopping. When tasks are withdrawn from a queue, the plan that chains them is cut short under
the same id. A robot that is lost loses its plan.

Transits in space and time (``coordinator.deconfliction`` ``prioritized`` or ``cbs``,
:mod:`fleet.coordinator.transits`): whenever plans go out, the transits of the robots getting
them and of those still in transit are planned together, around the robots that stand (no work,
or lost: their bodies stay). Each such plan keeps its schedule (the planned sim time of reaching
each transit waypoint), and as the robots report their progress a round is planned again when
one falls ``replan_lag_s`` further behind its schedule than another. A round that cannot be
planned falls back to local transits (A* on the floor plan).

Errands (:class:`Errand`, :meth:`Dispatcher.send_errand`) are trips that drive no task: to a
dock and to a waiting spot by one. With deconfliction they are planned in the rounds like the
transits to tasks, both when they go out and while they are under way.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from fleet.coordinator.job import ASSIGNED, LOST, TaskRecord
from fleet.coordinator.journal import Journal, Publish
from fleet.coordinator.planning import TaskPlanner
from fleet.coordinator.transits import PlannedTransit, TransitPlanner
from fleet.params import CoordinatorParams
from fleet.plan_chain import chain_length, chain_of, cut_plan, driven_ends
from fleet.protocol import Keys, Plan
from planners.polyline import ending_at, without_straight_vertices

# a robot's current plan that its statuses do not show it driving goes out again this many wall
# seconds after it was last sent
PLAN_RESEND_S = 2.0

log = logging.getLogger("coordinator")


@dataclass(frozen=True, eq=False)
class Errand:
    """A trip that drives no task (to a dock, or to a waiting spot by one): its plan's
    ``task`` name, the ``goal`` its transit ends at, the points driven straight on from
    there (onto the dock; none to a waiting spot), and its plan's ``kind`` (``dock``, ``wait``:
    :data:`fleet.protocol.ERRAND_KINDS`)."""

    task: str
    goal: tuple[float, float]
    tail: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    kind: str = "dock"


# what a robot of a round drives to: the chain of tasks its plan sweeps, or an errand
Leg = list[TaskRecord] | Errand


class Dispatcher:
    """The plans sent, their schedules, and the robots' progress along them."""

    def __init__(
        self,
        journal: Journal,
        planner: TaskPlanner,
        transits: TransitPlanner | None,
        params: CoordinatorParams,
        keys: Keys,
        publish: Publish,
    ) -> None:
        """``transits`` None: local transits only."""
        self.journal = journal
        self.job = journal.job
        self.planner = planner
        self.transits = transits
        self.params = params
        self.keys = keys
        self.publish = publish
        self.plans: dict[str, Plan] = {}
        self.plan_seq = 0
        # robot -> (plan id, planned sim time of reaching each transit waypoint)
        self.schedules: dict[str, tuple[int, np.ndarray]] = {}
        # robot -> (plan id, waypoint it heads for), from its status
        self.progress_of: dict[str, tuple[int, int]] = {}
        # robot -> wall time (monotonic) its plan was last sent
        self.sent_wall: dict[str, float] = {}
        self.last_transit_round = -math.inf
        # told when no transit takes a robot to its task: (robot, task, why)
        self.on_unreachable: Callable[[str, str, str], None] = lambda *_: None
        # the robots on an errand, and who is told each errand plan sent (a round's new one)
        self.errands: dict[str, Errand] = {}
        self.on_errand: Callable[[str, Plan], None] = lambda *_: None

    def resume(self, plans: dict[str, Plan], plan_seq: int) -> None:
        """Serve the plans a restarted coordinator's store holds, and number on from there."""
        self.plans = plans
        self.plan_seq = plan_seq

    def start_over(self) -> None:
        """A new job: no plan drives any of its tasks yet (plan ids number on)."""
        self.plans.clear()
        self.schedules.clear()
        self.progress_of.clear()

    def heard(self, rid: str, plan_id: int, waypoint: int) -> None:
        """``rid`` reports it drives plan ``plan_id``, heading for ``waypoint``."""
        self.progress_of[rid] = (plan_id, waypoint)

    def current(self, rid: str) -> Plan | None:
        """The plan ``rid`` should drive now: its last one, if that drives its current task."""
        plan = self.plans.get(rid)
        current = self.job.current(rid)
        if plan is None or current is None or current.task.id not in chain_of(plan):
            return None
        return plan

    def resend_unheard(self, now: float) -> None:
        """Send a robot its current plan again when its statuses do not show it driving it
        ``PLAN_RESEND_S`` after it was last sent: a plan lost, or dropped by an agent that did
        not hold its task yet when it came, would leave the robot idle with work assigned (and
        a robot without a plan is never stuck)."""
        for rid, plan in self.plans.items():
            at, r = self.progress_of.get(rid), self.job.robots.get(rid)
            if at is not None and at[0] == plan.plan_id:
                continue
            if r is None or r.liveness == LOST or r.acked_seq < r.award_seq:
                continue
            if self.current(rid) is None or now - self.sent_wall.get(rid, 0.0) < PLAN_RESEND_S:
                continue
            log.info("%s does not drive plan %d; sending it again", rid, plan.plan_id)
            self.sent_wall[rid] = now
            self.publish(self.keys.plan(rid), plan, True)

    def forget(self, rid: str) -> None:
        """``rid`` is lost, or its errand is over: it drives no plan."""
        self.plans.pop(rid, None)
        self.schedules.pop(rid, None)
        self.errands.pop(rid, None)

    def cut(self, withdrawn: list[str]) -> None:
        """Cut each plan before the first of its tasks in ``withdrawn``, under the same plan id,
        so its robot drives on to there without a stop; a plan whose first task is withdrawn is
        dropped (its robot stops when its award no longer holds the task)."""
        for rid, plan in list(self.plans.items()):
            chain = chain_of(plan)
            cut = next((j for j, t in enumerate(chain) if t in withdrawn), None)
            if cut == 0:
                self.forget(rid)
            elif cut is not None:
                self.plans[rid] = plan = cut_plan(plan, cut)
                self.journal.save_plan(rid, plan)
                self.publish(self.keys.plan(rid), plan, True)

    def dispatch(self) -> None:
        """Send a plan to every robot whose current task has none yet (once it has the award).
        With deconfliction, the transits of those robots and of the robots still in transit
        are planned together in space and time (:mod:`fleet.coordinator.transits`), and so are
        the transits of a round in which a robot fell ``replan_lag_s`` behind."""
        fresh = self._unplanned()
        if self.transits is None:
            for rid, chain in fresh.items():
                self._send_plan(rid, chain, None, {})
            return
        # without new plans a round is due only on a lag, looked at once per replan_lag_s
        if not fresh and self.journal.clock - self.last_transit_round < self.params.replan_lag_s:
            return
        in_transit = self._in_transit()
        if not fresh and not self._lagging(in_transit):
            return
        moving: dict[str, Leg] = {**in_transit, **fresh}
        transits = self._plan_transits(moving)
        ids = {rid: self.plan_seq + 1 + i for i, rid in enumerate(sorted(moving))}
        for rid in sorted(moving):
            if rid in fresh or rid in transits:
                self._send(rid, moving[rid], transits.get(rid), ids)

    def send_errand(self, rid: str, errand: Errand) -> Plan:
        """Send ``rid`` on ``errand`` from where it stands and return its plan. With
        deconfliction its transit is planned in a round with the robots in transit, whose plans
        go out again with the round's order of passage; without, or when the round fails, it is
        A* on the floor plan. Raises ValueError when no way leads to the goal."""
        if self.transits is None:
            return self._send_errand(rid, errand, None, {})
        moving: dict[str, Leg] = {**self._in_transit(), rid: errand}
        transits = self._plan_transits(moving)
        if rid not in transits:
            return self._send_errand(rid, errand, None, {})
        ids = {other: self.plan_seq + 1 + i for i, other in enumerate(sorted(moving))}
        for other in sorted(transits):
            self._send(other, moving[other], transits[other], ids)
        return self.plans[rid]

    def _unplanned(self) -> dict[str, list[TaskRecord]]:
        """The robots whose current task no plan drives yet, once they have acknowledged its
        award, each with the run of its queue one plan chains."""
        out = {}
        for rid, r in self.job.robots.items():
            if r.liveness == LOST or r.xy is None:
                continue
            queue = self.job.queue(rid)
            plan = self.plans.get(rid)
            if not queue or r.acked_seq < r.award_seq:
                continue
            if plan is not None and queue[0].task.id in chain_of(plan):
                continue
            out[rid] = queue[: chain_length([(rec.task, rec.reverse) for rec in queue])]
        return out

    def _in_transit(self) -> dict[str, Leg]:
        """The robots driving a planned transit, with their chains or errands: by their last
        status, or sent one so recently that no status of it has come yet."""
        out: dict[str, Leg] = {}
        for rid, (plan_id, _arrivals) in self.schedules.items():
            plan, r = self.plans.get(rid), self.job.robots[rid]
            if plan is None or plan.plan_id != plan_id or r.liveness == LOST:
                continue
            at = self.progress_of.get(rid)
            if not (at is None or at[0] != plan_id or at[1] < plan.sweep_from):
                continue
            errand = self.errands.get(rid)
            if errand is not None and errand.task == plan.task:
                out[rid] = errand
                continue
            chain = [self.job.tasks[t] for t in chain_of(plan)]
            if chain and all(rec.state == ASSIGNED and rec.owner == rid for rec in chain):
                out[rid] = chain
        return out

    def _lagging(self, in_transit: dict[str, Leg]) -> bool:
        """Whether one robot in transit has fallen ``replan_lag_s`` further behind its schedule
        than another. Robots that are all late alike keep their plans: the order of passage
        holds whatever the delays, and only a robot that makes the others wait for it costs
        time."""
        lag_s = self.params.replan_lag_s
        lags = {}
        for rid in in_transit:
            plan_id, arrivals = self.schedules[rid]
            at = self.progress_of.get(rid)
            if at is not None and at[0] == plan_id and 0 < at[1] < len(arrivals):
                lags[rid] = self.journal.clock - arrivals[at[1]]
        if len(lags) < 2 or max(lags.values()) - min(lags.values()) <= lag_s:
            return False
        late = max(lags, key=lags.__getitem__)
        self.journal.event(
            "behind", late, "", f"{lags[late] - min(lags.values()):.1f} s behind the others"
        )
        return True

    def _plan_transits(self, moving: dict[str, Leg]) -> dict[str, PlannedTransit]:
        """One round of transits: ``moving`` robots to the start of their chains or to their
        errands' goals, around the robots that stand (no work, or lost); {} (local transits)
        if the round fails."""
        assert self.transits is not None
        self.last_transit_round = self.journal.clock
        parked = {
            rid: r.xy
            for rid, r in self.job.robots.items()
            if r.xy is not None
            and rid not in moving
            and (r.liveness == LOST or (r.ready and self.job.current(rid) is None))
        }
        goals = {rid: _goal(leg) for rid, leg in moving.items()}
        froms = {rid: self.job.robots[rid].xy for rid in moving}
        t0 = time.perf_counter()
        plan, transits = self.transits.plan(
            self.journal.clock, {rid: (froms[rid], goals[rid]) for rid in moving}, parked
        )
        ms = 1e3 * (time.perf_counter() - t0)
        if plan.status == "unreachable":
            for rid in plan.unreachable:
                task = _task_of(moving[rid]) if rid in moving else ""
                self.journal.event("unreachable", rid, task, plan.message)
            log.warning("transits not planned: %s; local transits instead", plan.message)
        elif plan.status != "success":
            self.journal.event(
                "transits", "", "", f"failed: {plan.message}; local transits instead"
            )
            log.warning("transits not planned: %s; local transits instead", plan.message)
        else:
            self.journal.event(
                "transits",
                "",
                "",
                f"{len(moving)} robots by {plan.method} in {ms:.0f} ms, {len(parked)} standing",
            )
        return transits

    def _send(
        self, rid: str, leg: Leg, transit: PlannedTransit | None, ids: dict[str, int]
    ) -> None:
        if isinstance(leg, Errand):
            self._send_errand(rid, leg, transit, ids)
        else:
            self._send_plan(rid, leg, transit, ids)

    def _send_errand(
        self, rid: str, errand: Errand, transit: PlannedTransit | None, ids: dict[str, int]
    ) -> Plan:
        """Plan ``rid``'s ``errand`` (by ``transit`` if planned in space and time, then on to
        the goal, else A* on the floor plan; raises ValueError when no way leads there) and
        send it."""
        r = self.job.robots[rid]
        assert r.xy is not None
        if transit is not None:
            leg = ending_at(transit.waypoints, errand.goal)
        else:
            path = self.planner.transit.path(np.asarray(r.xy, dtype=float), np.array(errand.goal))
            leg = without_straight_vertices(np.asarray(path, dtype=float))
        waypoints = np.vstack([leg, errand.tail]) if len(errand.tail) else leg
        self.errands[rid] = errand
        plan = self._publish(
            rid, errand.task, waypoints, len(waypoints) - 1, [], [], transit, ids, errand.kind
        )
        self.on_errand(rid, plan)
        return plan

    def _send_plan(
        self,
        rid: str,
        chain: list[TaskRecord],
        transit: PlannedTransit | None,
        ids: dict[str, int],
    ) -> None:
        """Plan ``rid``'s drive through ``chain`` (by ``transit`` if planned in space and
        time, its waits naming the peers' new plans by ``ids``) and send it."""
        r = self.job.robots[rid]
        assert r.xy is not None
        pairs = [(rec.task, rec.reverse) for rec in chain]
        points = transit.waypoints if transit is not None else None
        try:
            waypoints, starts = self.planner.drive(r.xy, pairs, points)
        except ValueError as e:
            self.on_unreachable(rid, chain[0].task.id, str(e))
            return
        self.errands.pop(rid, None)
        starts = [int(i) for i in starts]
        self._publish(
            rid,
            chain[0].task.id,
            waypoints,
            starts[0],
            [rec.task.id for rec in chain],
            starts,
            transit,
            ids,
        )

    def _publish(
        self,
        rid: str,
        task: str,
        waypoints: np.ndarray,
        sweep_from: int,
        chain: list[str],
        starts: list[int],
        transit: PlannedTransit | None,
        ids: dict[str, int],
        kind: str = "clean",
    ) -> Plan:
        """Number, record and send ``rid``'s plan of ``kind``, with its transit's order of
        passage (its waits naming the peers' new plans by ``ids``) and schedule if planned in a
        round."""
        self.plan_seq = max(self.plan_seq + 1, ids.get(rid, 0))
        # a robot standing in the round (no work, stuck or lost) is planned round, not waited
        # for: it drives no plan of the round whose progress could release the wait
        waits = tuple(w for w in transit.waits if w[1] in ids) if transit is not None else ()
        plan = Plan(
            self.journal.clock,
            self.plan_seq,
            task,
            waypoints,
            sweep_from,
            chain,
            np.array(starts, dtype=np.int32),
            np.array([w[0] for w in waits], dtype=np.int32),
            [w[1] for w in waits],
            np.array([ids[w[1]] for w in waits], dtype=np.int32),
            np.array([w[2] for w in waits], dtype=np.int32),
            kind,
        )
        self.plans[rid] = plan
        if transit is not None:
            self.schedules[rid] = (plan.plan_id, transit.arrivals_s)
        else:
            self.schedules.pop(rid, None)
        self.journal.save_plan(rid, plan)
        self.journal.set_meta(plan_seq=self.plan_seq)
        self.sent_wall[rid] = time.monotonic()
        self.publish(self.keys.plan(rid), plan, True)
        return plan


def _goal(leg: Leg) -> tuple[float, float]:
    """Where a robot's transit of a round ends: its errand's goal, or its chain's start."""
    if isinstance(leg, Errand):
        return leg.goal
    return _xy(driven_ends(leg[0].task, leg[0].reverse)[0])


def _task_of(leg: Leg) -> str:
    return leg.task if isinstance(leg, Errand) else leg[0].task.id


def _xy(point: np.ndarray) -> tuple[float, float]:
    return float(point[0]), float(point[1])
