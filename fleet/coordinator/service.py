"""The coordinator process: owns the job — who cleans what — and runs the market.

Phases: ``gathering`` (waiting for the expected robots to be ready), ``auction`` (the first
allocation), ``cleaning`` (``exploring`` for an exploring fleet), ``done`` (every task done)
or ``incomplete`` (every task done but some no robot could reach, named in the ``finished``
event). With ``--loop`` a finished job is followed by the next: the floor planned again, every
task open, ``auction`` again. This shell wires the parts to the bus and runs the main loop; each
part has one job:

- :class:`fleet.coordinator.job.Job`: the job's state and rules (tasks, owners, swept pieces,
  robots), kept on disk by :class:`fleet.coordinator.store.JobStore` through
  :class:`fleet.coordinator.journal.Journal`, which also tells every change as an event;
- :class:`fleet.coordinator.auctioneer.Auctioneer`: calls, bids, the winner of each round
  (sequential single-item auctions, Koenig et al. 2006; the pricing is ``planners.auction``);
- :class:`fleet.coordinator.market.Market`: what goes on sale, and what a sale, a swept task,
  a lost robot or an idle one changes;
- :class:`fleet.coordinator.awards.Awards`: each robot's queue, sent until acknowledged;
- :class:`fleet.coordinator.dispatcher.Dispatcher`: plans and transits;
- its features, each a :class:`fleet.coordinator.parts.Part` handed in (batteries, exploring,
  a stored map's check and changes: :func:`fleet.coordinator.build.build_coordinator` picks
  them), whose hooks this loop and the market call, so any combination of them runs.

A robot is lost when its liveliness token goes (a dead process) or its wall-clock heartbeat is
silent for ``coordinator.heartbeat_timeout_s`` (a hung one; checked in the main loop and before
each auction round); one heard from again rejoins. The coordinator knows only what the robots
report, never the simulator's poses.

Its clock is the simulator's (``sim/clock``), as :class:`fleet.plausible.SimClock` believes it;
no robot's message moves it. Each receiver checks what it hears against what it knows
(:mod:`fleet.plausible`) and drops, counts and logs what cannot be: a pose, status, heartbeat or
acknowledgement from a robot not in the job (no liveliness token heard), a pose or status
stamped (with the scan it answers) more than a clock step ahead of the clock, and a pose the
robot cannot have driven to since its last. Heartbeats and acknowledgements carry the agent's
clock, which moves nothing here; they are not judged by it. Poses and statuses that come
before its clock has synced (a started or resumed coordinator, within a few clock messages) are
dropped uncounted. Its counts of malformed and implausible messages go out in ``coord/state``
and to the store's meta (``dropped``).
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager

from fleet.bus import Bus
from fleet.coordinator.auctioneer import Auctioneer
from fleet.coordinator.awards import Awards
from fleet.coordinator.beats import Beats
from fleet.coordinator.dispatcher import Dispatcher
from fleet.coordinator.dropped import Dropped
from fleet.coordinator.job import (
    ASSIGNED,
    BLOCKED,
    LOST,
    REJOINED,
    STRANDED,
    UNREACHABLE,
    GivenUpWaypoints,
    Job,
    TaskRecord,
)
from fleet.coordinator.journal import Journal
from fleet.coordinator.looping import next_job
from fleet.coordinator.market import Market
from fleet.coordinator.parts import Part, Parts
from fleet.coordinator.planning import TaskPlanner
from fleet.coordinator.store import JobStore
from fleet.coordinator.transits import TransitPlanner
from fleet.floor_map import pack_grid
from fleet.params import CoordinatorParams
from fleet.plausible import STRANGER_GRACE_S, Bounds, PoseTrack, SimClock, Strangers
from fleet.protocol import (
    AwardAck,
    Bids,
    Clock,
    FleetState,
    Heartbeat,
    Plan,
    PoseEstimate,
    Request,
    RobotStatus,
)
from planners.auction import Task

log = logging.getLogger("coordinator")

LOOP_S = 0.05
# the phases of a finished job: its end is final (a robot back later reopens nothing)
FINISHED = ("done", "incomplete")
STATE_PERIOD_S = 0.5
PERSIST_ROBOTS_S = 1.0


class Coordinator:
    """The coordinator's parts, wired to the bus, and its main loop."""

    def __init__(
        self,
        bus: Bus,
        planner: TaskPlanner,
        expected: int,
        params: CoordinatorParams,
        store: JobStore | None = None,
        transits: TransitPlanner | None = None,
        *,
        bounds: Bounds,
        parts: Sequence[Part] = (),
    ) -> None:
        """``parts``: its features (:mod:`fleet.coordinator.parts`), wired before any message
        is heard."""
        self.bus = bus
        self.keys = bus.keys
        self.planner = planner
        self.expected = expected
        self.params = params
        self.store = store
        self.lock = threading.RLock()
        self.beats = Beats()
        self.stop = threading.Event()
        self.wake = threading.Event()
        self.job = Job(planner.params, planner.robot, planner.wall_clearance)
        self.phase = "gathering"
        self.given_up = GivenUpWaypoints()
        resumed = load_job(self.job, store)
        meta = resumed or {}
        self.journal = Journal(
            self.job, store, self.keys, bus.publish, float(meta.get("clock", 0.0))
        )
        self.awards = Awards(self.journal, self.keys, bus.publish)
        self.dispatcher = Dispatcher(
            self.journal, planner, transits, params, self.keys, bus.publish
        )
        self.parts = Parts(parts)
        self.market = Market(
            self.journal, self.awards, self.dispatcher, self.lock, self.wake, self.stop, self.parts
        )
        self.market.stall_s = params.stall_s
        self.market.stall_progress_m = params.stall_progress_m
        self.dispatcher.on_unreachable = self.market.cannot_reach
        self.parts.wire(self)
        self.auctioneer = Auctioneer(
            self.keys,
            bus.publish,
            params,
            self.market.sell,
            self.stop,
            int(meta.get("round_seq", 0)),
            meta.get("rejected_bids", {}),  # type: ignore[arg-type]
        )
        self.bounds = bounds
        clock_key = self.keys.clock()
        self.sim_clock = SimClock(
            bounds.clock_step_s,
            lambda n, why: bus.drop_implausible(clock_key, "sim", why, n),
            self.journal.clock,
        )
        self.strangers = Strangers(STRANGER_GRACE_S, bus.drop_implausible)
        self.tracks: dict[str, PoseTrack] = {}
        self.drops = Dropped.resumed(bus, meta)
        if resumed is not None:
            assert store is not None
            self._resume(store, resumed)
        # robots join by their liveliness tokens, heard before anything they send
        bus.watch_alive("agent", self._on_join, self._on_leave)
        bus.subscribe(clock_key, Clock, self._on_clock)
        bus.subscribe(self.keys.all_robots("pose"), PoseEstimate, self._on_pose)
        bus.subscribe(self.keys.all_robots("status"), RobotStatus, self._on_status)
        bus.subscribe(self.keys.all_robots("heartbeat"), Heartbeat, self._on_heartbeat)
        bus.subscribe(self.keys.all_bids(), Bids, self.auctioneer.on_bid)
        bus.subscribe(self.keys.ack("*"), AwardAck, self._on_ack)
        bus.serve(self.keys.plan("*"), Request, self._on_plan_query)
        if self.parts.floor_plan:
            # the floor plan the tasks are cut from: robots price on it
            floor = pack_grid(planner.grid)
            bus.serve(self.keys.floor_map(), Request, lambda _req: floor)
        self.parts.serve()

    # ---- restart ------------------------------------------------------------------------

    def _resume(self, store: JobStore, meta: dict[str, object]) -> None:
        """Carry on the job ``store`` holds: the same plans, phase and counts."""
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
        self.market.need_auction = bool(self.job.open_tasks())
        log.info(
            "resumed the job from %s: %s, phase %s",
            store.path,
            ", ".join(f"{v} {k}" for k, v in self.job.counts().items()),
            self.phase,
        )
        self.journal.event("resumed", "", "", f"{len(self.job.tasks)} tasks")

    # ---- bus callbacks ------------------------------------------------------------------

    def _on_clock(self, _key: str, msg: Clock) -> None:
        if self.sim_clock.hear(msg.stamp):
            self.journal.heard(self.sim_clock.now)

    def implausible(self, key: str, rid: str, stamp: float | None = None) -> bool:
        """Drop (count and log) a message from ``rid`` that is not in the job (counted unless its
        token comes soon after: :class:`fleet.plausible.Strangers`), or with a sensor ``stamp``
        farther ahead of the clock than a robot's can be; whether it was dropped. A
        stamped one that comes before the clock has synced (since this coordinator started)
        is dropped uncounted: there is no time to judge it by yet, and one stamped far ahead,
        believed, would stand as the robot's newest pose and hide every real one after it.
        Call with the lock held."""
        if rid not in self.job.robots:
            self.strangers.heard(key, rid, "not in the job: no liveliness token of it heard")
            return True
        if stamp is not None and not self.sim_clock.synced:
            return True
        if stamp is not None and self.sim_clock.ahead(stamp, strict=True):
            why = f"stamped {stamp:.3f} s, past the sim clock at {self.sim_clock.now:.3f} s"
        else:
            return False
        self.bus.drop_implausible(key, rid, why)
        return True

    def _on_pose(self, key: str, msg: PoseEstimate) -> None:
        rid = self.keys.robot_of(key)
        with self.lock:
            if self.implausible(key, rid, msg.stamp):
                return
            track = self.tracks.get(rid)
            if track is None:
                track = self.tracks[rid] = PoseTrack(
                    self.bounds.speed,
                    self.bounds.margin_m,
                    lambda n, why: self.bus.drop_implausible(key, rid, why, n),
                )
            if track.hear(msg.stamp, (msg.x, msg.y)):
                self.job.robots[rid].xy = (msg.x, msg.y)

    def _on_heartbeat(self, key: str, msg: Heartbeat) -> None:
        """Noted without the lock, applied if it is free (:mod:`fleet.coordinator.beats`)."""
        self.beats.note(key, msg)
        if self.lock.acquire(blocking=False):
            try:
                self._apply_beats()
            finally:
                self.lock.release()

    def _apply_beats(self) -> None:
        """The heartbeats heard since the last call, as they arrived (call with the lock)."""
        for key, heard, msg in self.beats.take():
            rid = self.keys.robot_of(key)
            # stamped with the agent's clock, which moves nothing here: a wrong one must not
            # turn a working robot into a lost one
            if self.implausible(key, rid):
                continue
            r = self.job.robots[rid]
            r.heartbeat_wall = max(r.heartbeat_wall, heard)
            was_ready, r.ready = r.ready, msg.ready
            if r.liveness == LOST:
                r.liveness = REJOINED
                self.journal.event("rejoined", rid, "", "heard from again; bids afresh")
                if self.phase not in FINISHED:
                    # a finished job stays so: what it left out is named in its end
                    self.market.rejoined(rid)
            elif r.ready and not was_ready and self.phase != "gathering":
                self.market.rebalance()

    def _on_join(self, rid: str) -> None:
        self.strangers.joined(rid)
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
            if self.stop.is_set():
                return  # the fleet is shutting down: its tokens going are no losses
            if rid in self.job.robots and self.job.robots[rid].liveness != LOST:
                self.market.lose(rid, "its liveliness token is gone")

    def _on_status(self, key: str, msg: RobotStatus) -> None:
        rid = self.keys.robot_of(key)
        with self.lock:
            if self.implausible(key, rid, msg.stamp):
                return
            r = self.job.robots[rid]
            r.state, r.task, r.progress = msg.state, msg.task, msg.progress
            self.dispatcher.heard(rid, msg.plan_id, msg.waypoint)
            if msg.plan_id >= 0 and self.given_up.report(rid, msg.plan_id, msg.skipped):
                log.warning("%s has given up %d waypoint(s)", rid, self.given_up.by_robot[rid])
            self.market.swept(rid, msg, self.dispatcher.plans.get(rid))
            self.market.observe(rid, msg)
            self.parts.observe(rid, msg)

    def _on_ack(self, key: str, msg: AwardAck) -> None:
        rid = self.keys.robot_of(key)
        with self.lock:
            if self.implausible(key, rid):
                return
            if self.awards.acked(rid, msg):
                self.wake.set()
            else:
                self.bus.drop_implausible(key, rid, f"acknowledges for {msg.robot!r}")

    def _on_plan_query(self, req: Request) -> Plan:
        with self.lock:
            plan = self.dispatcher.current(req.sender)
        if plan is None:
            raise LookupError(f"no plan for {req.sender} now")
        return plan

    # ---- liveliness ---------------------------------------------------------------------

    def _check_heartbeats(self) -> None:
        self._apply_beats()
        now = time.time()
        for rid, r in list(self.job.robots.items()):
            if r.liveness != LOST and now - r.heartbeat_wall > self.params.heartbeat_timeout_s:
                self.market.lose(rid, f"no heartbeat for {now - r.heartbeat_wall:.1f} s")

    # ---- main loop ----------------------------------------------------------------------

    def close(self) -> None:
        """Stop, and close the store: what the handlers still hear (the robots' tokens going as
        the fleet shuts down) is no longer part of the job."""
        self.stop.set()
        with self.lock:
            store, self.store, self.journal.store = self.store, None, None
            if store is not None:
                store.close()

    def run(self, grace_s: float, loop: bool = False) -> None:
        """Plan the tasks (unless resumed), then run the job; with ``loop``, job after job."""
        self.parts.start()
        if not self.job.tasks:
            self.phase = "planning"  # the simulator's clock waits while the state says so
            with repeating(self._publish_state, self.lock, STATE_PERIOD_S):
                self._plan_tasks()
            self.phase = "gathering"
        gather_start = time.monotonic()
        last_state = last_robots = 0.0
        while not self.stop.is_set():
            self.wake.wait(LOOP_S)
            self.wake.clear()
            auction_due = False
            self.strangers.flush()
            with self.lock:
                self._apply_beats()
                if self.phase == "gathering":
                    waited = time.monotonic() - gather_start
                    if gathered(len(self.job.market()), self.expected, waited, grace_s):
                        self.phase = "auction"
                        self.market.need_auction = True
                        self.journal.set_meta(phase=self.phase)
                else:
                    self._check_heartbeats()
                    self.market.check_stalls()
                    self.parts.check_stalls()
                    self.parts.tick()
                    auction_due = self.market.serve_idle()
                auction_due = auction_due or self.market.need_auction
            self.parts.unlocked()
            if loop and self.phase in FINISHED:
                self.phase = next_job(self.market, self.planner, self.lock)
            elif self.phase != "gathering" and auction_due:
                self.market.auction(self.auctioneer, self._check_heartbeats)
            with self.lock:
                if self.phase != "gathering":
                    self._send_due()
                now = time.monotonic()
                if self.store is not None and now - last_robots > PERSIST_ROBOTS_S:
                    last_robots = now
                    self._persist(self.store)
                if now - last_state > STATE_PERIOD_S:
                    last_state = now
                    self._publish_state()

    def _send_due(self) -> None:
        """Send the awards and plans due, and move the phase on."""
        self.awards.send()
        self.dispatcher.dispatch()
        self.dispatcher.resend_unheard(time.monotonic())
        if self._finished() and self.phase not in FINISHED:
            left = self.job.left_out()
            self.phase = "incomplete" if left else "done"
            log.info(self.given_up.finished_message())
            detail = ""
            if left:
                area = sum(r.task.area_m2 for r in left)
                detail = f"incomplete: {area:.2f} m² in {len(left)} task(s) left out: "
                detail += ", ".join(_left_out(r) for r in left)
                log.warning("the job ends %s", detail)
            self.journal.event("finished", "", "", detail)
            self.journal.set_meta(phase=self.phase)
        elif self.phase == "auction" and not self.job.open_tasks():
            self.phase = self.parts.working

    def work_over(self) -> bool:
        """Whether the job's work is over: every task done or left out, unless a part decides
        (an exploring one: no frontier left)."""
        return self.parts.work_over(self.job)

    def _finished(self) -> bool:
        """The job ends once its work is over and every part lets it (robots home)."""
        return self.work_over() and self.parts.settled()

    def _persist(self, store: JobStore) -> None:
        """What changes too often to save at each change: the robots, the counters."""
        store.save_robots(list(self.job.robots.values()))
        malformed, implausible = self.drops.on_bus()
        store.set_meta(
            phase=self.phase,
            clock=self.journal.clock,
            rejected_bids=self.auctioneer.rejected(),
            given_up_waypoints=self.given_up.to_json(),
            dropped={"malformed": malformed, "implausible": implausible},
        )

    def _plan_tasks(self) -> None:
        """The floor's tour cut into tasks, unless a part makes the job's tasks."""
        if not self.parts.make_tasks():
            plan_tour(self.planner, self.lock, self._take_tasks)

    def _take_tasks(self, tasks: tuple[Task, ...]) -> None:
        self.job.add_tasks(tasks)
        self.journal.save_tasks(*self.job.tasks)
        self.journal.set_meta(expected_robots=self.expected, **self.planner.meta)
        self.journal.event("planned", "", "", f"{len(tasks)} tasks")

    def _publish_state(self) -> None:
        state = fleet_state(
            self.job, self.journal.clock, self.phase, self.drops.in_job(self.auctioneer.rejected())
        )
        self.bus.publish(self.keys.coord_state(), state, control=True)


def load_job(job: Job, store: JobStore | None) -> dict[str, object] | None:
    """Fill ``job`` from ``store``; its counters if it holds a job to resume, else None."""
    if store is None:
        return None
    store.load_job(job)
    return store.meta() if job.tasks else None


def fleet_state(job: Job, clock: float, phase: str, dropped: tuple[int, int]) -> FleetState:
    """What ``coord/state`` tells: the phase, the robots (idle, lost), the task counts and the
    messages dropped (malformed, implausible)."""
    counts = job.counts()
    robots = sorted(job.robots)
    return FleetState(
        clock,
        phase,
        robots,
        sorted(r for r in robots if job.current(r) is None),
        sorted(r for r in robots if job.robots[r].liveness == LOST),
        counts["open"],
        counts[ASSIGNED],
        counts["done"],
        counts[BLOCKED] + counts[UNREACHABLE] + counts[STRANDED],
        *dropped,
    )


def _left_out(rec: TaskRecord) -> str:
    """A task left out, for the end message: its id, area, where it lies and why."""
    x, y = rec.task.path.mean(axis=0)
    if rec.state == STRANDED:
        why = "stranded: no robot left with charge"
    elif rec.blocked_by:
        why = f"behind {rec.blocked_by}'s body"
    else:
        why = f"tried by {', '.join(sorted(rec.tried))}: every robot that could still work"
    return f"{rec.task.id} ({rec.task.area_m2:.2f} m² at ({x:.1f}, {y:.1f}), {why})"


def gathered(ready: int, expected: int, waited: float, grace_s: float) -> bool:
    """Whether the job may start: all ``expected`` robots are ready, or some are and the
    robots' start has been waited for longer than ``grace_s``."""
    if ready >= expected or (ready > 0 and waited > grace_s):
        if ready < expected:
            log.warning("only %d of %d robots are ready; starting with them", ready, expected)
        return True
    return False


@contextlib.contextmanager
def repeating(publish: Callable[[], None], lock: AbstractContextManager, period_s: float):
    """``publish`` (with ``lock`` held) now and every ``period_s`` until the block ends, on a
    thread of its own: a state the block's long work is in reaches a process that subscribes
    late, or missed it."""
    done = threading.Event()

    def loop() -> None:
        while True:
            with lock:
                publish()
            if done.wait(period_s):
                return

    thread = threading.Thread(target=loop, name="repeating", daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()


def plan_tour(
    planner: TaskPlanner, lock: AbstractContextManager, take: Callable[[tuple[Task, ...]], None]
) -> tuple[Task, ...]:
    """The tour cut into tasks, handed to ``take`` with ``lock`` held. The lock is not held
    while the tour is planned (a second or more on a large floor), so ``planner.planning`` says
    so meanwhile: a map change found then (``fleet.coordinator.map_changes``) waits, and is
    taken once the tasks are the job's (re-planning for it held a home run up by 50 s)."""
    t0 = time.perf_counter()
    with lock:
        planner.planning = True
    try:
        tasks = planner.tasks()
        with lock:
            take(tasks)
    finally:
        with lock:
            planner.planning = False
    log.info("planned %d tasks in %.2f s", len(tasks), time.perf_counter() - t0)
    return tasks
