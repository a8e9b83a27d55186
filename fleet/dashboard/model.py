"""Watching a run: the dashboard's model of the fleet, built from bus messages only.

:class:`FleetWatcher` is the model: each ``on_*`` method takes one decoded message (or a
liveliness change) and updates it; :meth:`FleetWatcher.snapshot` copies what a view needs into
a :class:`FleetSnapshot`, which :mod:`fleet.dashboard.view` draws. Nothing here draws or reads
a terminal, so tests feed recorded messages straight in.

:class:`BusFeed` connects a model to the bus. Streams that come at control rate from every
robot (true poses, intents, status, the sim clock) go into Zenoh ring buffers and are decoded
by :meth:`BusFeed.pump` on the view's thread, only the newest per key: a Python callback and a
decode per sample would cost the dashboard more than it draws. The job's
messages (events, fleet state, plans, collisions, heartbeats, coverage) arrive by callback.
A background thread fetches the floor plan (served by the coordinator) and the cleaned area
(served by the simulator) once a second.

The dashboard reads truth (where the robots really are) and commands nothing.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fleet.bus import Bus
from fleet.floor_map import unpack_grid
from fleet.plausible import StampWatch
from fleet.protocol import (
    Clock,
    Collision,
    CoverageImage,
    CoverageSummary,
    DecodeError,
    FleetEvent,
    FleetState,
    Heartbeat,
    Intent,
    Keys,
    MapPatches,
    Message,
    Plan,
    Request,
    RobotStatus,
    TruthPose,
    decode,
    key_class,
)
from fleet.rundir import Dropped
from planners.grid import GridMap

log = logging.getLogger(__name__)

EVENTS_KEPT = 200
# routine events the view does not list; every event is in report.json
QUIET_EVENTS = ("awarded", "done", "auction")
# the coordinator's phases of a finished job: incomplete names work no robot could reach
FINISHED_PHASES = ("done", "incomplete")
# the phase of a fleet mapping an unknown home (`fleet explore`)
EXPLORING = "exploring"
# wall seconds over which message rates are averaged
RATE_WINDOW_S = 2.0
# sim seconds over which a robot's speed is averaged
SPEED_WINDOW_S = 1.0
# a robot whose heartbeat is older than this (wall seconds) shows as silent; the views pass
# coordinator.heartbeat_timeout_s, after which the coordinator counts the robot lost
SILENT_AFTER_S = 1.0
# ring buffers of the high-rate streams: room for a second of 10 robots at 4x speed
RING_CAPACITY = 2048
# how often the floor plan and the cleaned area are asked for, and how long a query may take
FETCH_PERIOD_S = 1.0
FETCH_TIMEOUT_S = 1.0


@dataclass
class RobotView:
    """What the model knows of one robot. ``pose`` is its true pose (x, y, theta) at sim time
    ``pose_stamp``; ``intent`` the (x, y) points of its path ahead; ``alive`` whether its
    liveliness token is there (None until heard of); ``gave_up`` the waypoints it gave up as
    unreachable over all its plans since the view first heard of it."""

    status: RobotStatus | None = None
    pose: tuple[float, float, float] | None = None
    pose_stamp: float = 0.0
    speed: float = 0.0
    intent: np.ndarray | None = None
    heartbeat_wall: float | None = None
    alive: bool | None = None
    gave_up: int = 0
    goal: tuple[float, float] | None = None
    recent: deque[tuple[float, float, float]] = field(default_factory=lambda: deque(maxlen=64))


@dataclass(frozen=True)
class EventLine:
    """One line of the events panel: wall time, kind (for colour) and text."""

    wall: float
    kind: str
    text: str


@dataclass(frozen=True)
class RobotRow:
    """One robot as the view shows it. ``liveness`` is alive, silent (no heartbeat for
    ``SILENT_AFTER_S``), lost (the coordinator says so or its liveliness token went) or
    unknown; ``restarts`` is None when no process table is known; ``gave_up`` counts the
    waypoints given up over all its plans since the view came; ``charge`` its battery's last
    reading (None without batteries) and ``charging`` whether a dock charges it; ``goal`` the
    last waypoint of its plan (exploring: the frontier it heads for)."""

    rid: str
    liveness: str
    state: str
    task: str
    progress: float | None
    speed: float
    heartbeat_age: float | None
    restarts: int | None
    gave_up: int
    pose: tuple[float, float, float] | None
    intent: np.ndarray | None
    charge: float | None = None
    charging: bool = False
    goal: tuple[float, float] | None = None


@dataclass(frozen=True)
class FleetSnapshot:
    """Everything a view draws, copied out of the model at one moment."""

    wall: float
    fleet: str
    phase: str
    sim_time: float
    coverage: float | None
    repetition: float | None
    tasks: tuple[int, int, int] | None
    eta_s: float | None
    robots: list[RobotRow]
    events: list[EventLine]
    rates: list[tuple[str, float]]
    floor: GridMap | None
    cleaned: CoverageImage | None
    collisions: int
    note: str = ""
    left_out: int = 0
    dropped: Dropped = field(default_factory=dict)


class RateMeter:
    """Messages per second per key class (:func:`fleet.protocol.key_class`), over a sliding
    window of wall time."""

    def __init__(self, window_s: float = RATE_WINDOW_S) -> None:
        self.window_s = window_s
        self._seen: dict[str, deque[tuple[float, int]]] = {}
        self._lock = threading.Lock()

    def count(self, key: str, n: int = 1, now: float | None = None) -> None:
        now = time.monotonic() if now is None else now
        pattern = key_class(key)
        with self._lock:
            seen = self._seen.setdefault(pattern, deque())
            seen.append((now, n))
            # pruned here too, not only when read: `fleet up --headless` never reads the rates
            while seen[0][0] < now - self.window_s:
                seen.popleft()

    def rates(self, now: float | None = None) -> list[tuple[str, float]]:
        """(pattern, messages per second), busiest first."""
        now = time.monotonic() if now is None else now
        out = []
        with self._lock:
            for pattern, seen in self._seen.items():
                while seen and seen[0][0] < now - self.window_s:
                    seen.popleft()
                out.append((pattern, sum(n for _, n in seen) / self.window_s))
        return sorted(out, key=lambda r: (-r[1], r[0]))


class FleetWatcher:
    """The dashboard's model of a fleet (see the module docstring). Thread-safe: callbacks
    on Zenoh threads and the view's thread both go through ``lock``."""

    def __init__(
        self,
        fleet: str = "default",
        silent_after_s: float = SILENT_AFTER_S,
        watch: StampWatch | None = None,
    ) -> None:
        """``watch``: the sim clock the view judges stamps by (messages stamped past it are
        dropped and counted) and the robots in the job, fed by :meth:`on_alive` (statuses,
        intents and heartbeats of other robots are dropped and counted); None takes every
        message as it comes (tests, the dashboard bench)."""
        self.keys = Keys(fleet)
        self.watch = watch
        self.silent_after_s = silent_after_s
        self.lock = threading.Lock()
        self.clock = 0.0
        self.coverage: CoverageSummary | None = None
        self.fleet: FleetState | None = None
        self.robots: dict[str, RobotView] = {}
        self.collisions: list[Collision] = []
        self.events: deque[EventLine] = deque(maxlen=EVENTS_KEPT)
        self.rates = RateMeter()
        self.floor: GridMap | None = None
        self.cleaned: CoverageImage | None = None
        self.restarts: dict[str, int] | None = None
        self._unseen: list[EventLine] = []
        self.started_at: float | None = None
        self.started_wall: float | None = None
        self._first_state: tuple[float, int] | None = None
        self.finished_at: float | None = None
        # the messages this view's own process dropped: (name, malformed, implausible)
        self.own_dropped: tuple[str, int, int] | None = None

    def _robot(self, rid: str) -> RobotView:
        return self.robots.setdefault(rid, RobotView())

    def _event(self, wall: float, kind: str, text: str) -> None:
        line = EventLine(wall, kind, text)
        self.events.append(line)
        self._unseen.append(line)

    # ---- messages in ----------------------------------------------------------------------

    def _ahead(self, key: str, sender: str, stamp: float) -> bool:
        return self.watch is not None and self.watch.ahead(key, sender, stamp)

    def _stranger(self, key: str, rid: str) -> bool:
        return self.watch is not None and self.watch.stranger(key, rid)

    def on_clock(self, _key: str, m: Clock) -> None:
        # the view samples the clock at each redraw; its watch hears every clock message and
        # has counted a forged one already
        if self.watch is not None and self.watch.clock.ahead(m.stamp, strict=True):
            return
        with self.lock:
            self.clock = max(self.clock, m.stamp)

    def on_coverage(self, key: str, m: CoverageSummary) -> None:
        if self._ahead(key, "sim", m.stamp):
            return
        with self.lock:
            self.coverage = m

    def on_fleet(self, key: str, m: FleetState) -> None:
        if self._ahead(key, "coordinator", m.stamp):
            return
        with self.lock:
            self.fleet = m
            if self._first_state is None:
                self._first_state = (time.time(), m.tasks_done)
            for rid in m.robots:
                self._robot(rid)
            if m.phase in FINISHED_PHASES and self.finished_at is None:
                self.finished_at = m.stamp

    def on_status(self, key: str, m: RobotStatus) -> None:
        rid = self.keys.robot_of(key)
        if self._stranger(key, rid) or self._ahead(key, rid, m.stamp):
            return
        with self.lock:
            robot = self._robot(rid)
            prev = robot.status
            if prev is not None and prev.stamp > m.stamp:
                return
            robot.status = m
            if prev is None:
                # a view that came late: what was given up before it came is not news
                robot.gave_up = m.skipped
                return
            # an agent counts the waypoints it gave up afresh for each plan
            new_plan = m.plan_id != prev.plan_id or m.skipped < prev.skipped
            more = m.skipped if new_plan else m.skipped - prev.skipped
            if more > 0:
                robot.gave_up += more
                rest = f"{m.task:<8} {more} unreachable waypoint(s), {robot.gave_up} in all"
                self._event(time.time(), "gave up", _line(m.stamp, "gave up", rid, rest))

    def on_truth(self, key: str, m: TruthPose) -> None:
        rid = self.keys.robot_of(key)
        if self._ahead(key, "sim", m.stamp):
            return
        with self.lock:
            robot = self._robot(rid)
            if robot.pose is not None and m.stamp < robot.pose_stamp:
                return
            robot.pose = (m.x, m.y, m.theta)
            robot.pose_stamp = m.stamp
            recent = robot.recent
            recent.append((m.stamp, m.x, m.y))
            while len(recent) > 2 and recent[1][0] <= m.stamp - SPEED_WINDOW_S:
                recent.popleft()
            t0, x0, y0 = recent[0]
            robot.speed = math.hypot(m.x - x0, m.y - y0) / (m.stamp - t0) if m.stamp > t0 else 0.0

    def on_intent(self, key: str, m: Intent) -> None:
        rid = self.keys.robot_of(key)
        if self._stranger(key, rid):
            return
        with self.lock:
            self._robot(rid).intent = m.points[:, 1:3].copy()

    def on_heartbeat(self, key: str, _m: Heartbeat) -> None:
        rid = self.keys.robot_of(key)
        if self._stranger(key, rid):
            return
        with self.lock:
            self._robot(rid).heartbeat_wall = time.time()

    def on_plan(self, key: str, m: Plan) -> None:
        # coord/plan/<robot>
        rid = str(key).rsplit("/", 1)[-1]
        with self.lock:
            if rid and len(m.waypoints):
                self._robot(rid).goal = (float(m.waypoints[-1][0]), float(m.waypoints[-1][1]))
            if self.started_at is None or m.stamp < self.started_at:
                self.started_at = m.stamp
            if self.started_wall is None:
                self.started_wall = time.time()

    def on_event(self, _key: str, m: FleetEvent) -> None:
        if m.kind in QUIET_EVENTS:
            return
        with self.lock:
            if m.kind == "planned" and (self.started_wall is None or m.wall < self.started_wall):
                self.started_wall = m.wall
            self._event(m.wall, m.kind, _event_text(m))

    def on_collision(self, _key: str, m: Collision) -> None:
        with self.lock:
            self.collisions.append(m)
            what = f"robot {m.other}" if m.kind == "robot" else m.kind
            rest = f"with {what} at ({m.x:.2f}, {m.y:.2f})"
            self._event(time.time(), "contact", _line(m.stamp, "contact", m.robot, rest))

    def on_alive(self, rid: str, alive: bool) -> None:
        """An agent's liveliness token appeared (``alive``) or went: it is in the job."""
        if self.watch is not None:
            self.watch.join(rid)
        with self.lock:
            robot = self._robot(rid)
            robot.alive = alive
            if alive:
                robot.heartbeat_wall = time.time()

    def on_floor(self, m: MapPatches) -> None:
        with self.lock:
            self.floor = unpack_grid(m)

    def on_cleaned(self, m: CoverageImage) -> None:
        with self.lock:
            self.cleaned = m

    def set_own_dropped(self, name: str, malformed: int, implausible: int) -> None:
        """The messages the view's own process (``name``) has dropped."""
        with self.lock:
            self.own_dropped = (name, malformed, implausible)

    def dropped(self) -> Dropped:
        """The messages each process has dropped as malformed and as implausible, as far as it
        has told: the simulator (coverage), the coordinator (its state), each agent (its status)
        and this view's own process."""
        with self.lock:
            return self._dropped()

    def _dropped(self) -> Dropped:
        out: Dropped = {}
        if self.coverage is not None:
            out["sim"] = (self.coverage.decode_errors, self.coverage.implausible)
        if self.fleet is not None:
            out["coordinator"] = (self.fleet.decode_errors, self.fleet.implausible)
        for rid, v in sorted(self.robots.items()):
            if v.status is not None:
                out[rid] = (v.status.decode_errors, v.status.implausible)
        if self.own_dropped is not None:
            name, malformed, implausible = self.own_dropped
            out[name] = (malformed, implausible)
        return out

    def set_restarts(self, restarts: dict[str, int]) -> None:
        """How often each process was restarted, from the run's process table."""
        with self.lock:
            self.restarts = dict(restarts)

    def note(self, kind: str, text: str) -> None:
        """An operator's action or a local problem, shown among the events."""
        with self.lock:
            self._event(time.time(), kind, text)

    # ---- what views read ------------------------------------------------------------------

    def take_events(self) -> list[str]:
        """The events (but the routine ones) since the last call, one line each."""
        with self.lock:
            unseen, self._unseen = self._unseen, []
        return [_stamped(e) for e in unseen]

    @property
    def done(self) -> bool:
        """Whether the job is finished: every task done, or done but for work left out."""
        with self.lock:
            return self.fleet is not None and self.fleet.phase in FINISHED_PHASES

    @property
    def phase(self) -> str:
        with self.lock:
            return self.fleet.phase if self.fleet is not None else "starting"

    def makespan(self) -> float | None:
        """Sim seconds from the first plan given to the job done; None until it is."""
        with self.lock:
            if self.finished_at is None:
                return None
            return self.finished_at - (self.started_at or 0.0)

    def snapshot(self, now: float | None = None, events: int = EVENTS_KEPT) -> FleetSnapshot:
        """A copy of what the view draws at wall time ``now``, with the last ``events``."""
        now = time.time() if now is None else now
        rates = self.rates.rates()
        with self.lock:
            f = self.fleet
            lost = set(f.lost) if f else set()
            rows = [self._row(rid, v, rid in lost, now) for rid, v in sorted(self.robots.items())]
            tasks = (f.tasks_open, f.tasks_assigned, f.tasks_done) if f else None
            cov = self.coverage
            return FleetSnapshot(
                wall=now,
                fleet=self.keys.fleet,
                phase=f.phase if f else "starting",
                sim_time=self.clock,
                coverage=cov.coverage if cov else None,
                repetition=cov.repetition if cov else None,
                tasks=tasks,
                eta_s=self._eta(now),
                robots=rows,
                events=list(self.events)[-events:] if events > 0 else [],
                rates=rates,
                floor=self.floor,
                cleaned=self.cleaned,
                collisions=len(self.collisions),
                left_out=f.tasks_left_out if f else 0,
                dropped=self._dropped(),
            )

    def _row(self, rid: str, v: RobotView, lost: bool, now: float) -> RobotRow:
        age = None if v.heartbeat_wall is None else max(0.0, now - v.heartbeat_wall)
        if lost or v.alive is False:
            liveness = "lost"
        elif age is not None and age > self.silent_after_s:
            liveness = "silent"
        elif v.alive or age is not None:
            liveness = "alive"
        else:
            liveness = "unknown"
        s = v.status
        restarts = None if self.restarts is None else self.restarts.get(rid, 0)
        return RobotRow(
            rid=rid,
            liveness=liveness,
            state=s.state if s else "",
            task=s.task if s else "",
            progress=s.progress if s else None,
            speed=v.speed,
            heartbeat_age=age,
            restarts=restarts,
            gave_up=v.gave_up,
            pose=v.pose,
            intent=v.intent,
            charge=s.charge if s and s.charge >= 0 else None,
            charging=bool(s and s.charging),
            goal=v.goal,
        )

    def _eta(self, now: float) -> float | None:
        """Wall seconds until the last task is done, at the pace tasks have been done so far
        (tasks are cut to about the same cleaning time): since the job was planned, or, for a
        view that came later and never heard of that, since the view first heard the job's
        state. None until a task is done in that time."""
        f = self.fleet
        if f is None:
            return None
        if f.phase in FINISHED_PHASES:
            return 0.0
        if self.started_wall is not None:
            since, done_then = self.started_wall, 0
        elif self._first_state is not None:
            since, done_then = self._first_state
        else:
            return None
        total = f.tasks_open + f.tasks_assigned + f.tasks_done
        done = f.tasks_done - done_then
        if done <= 0 or total == 0:
            return None
        return max(0.0, now - since) * (total - f.tasks_done) / done

    def line(self, wall_s: float) -> str:
        """One plain line of the fleet's state, for logs and terminals without a screen."""
        with self.lock:
            cov = self.coverage
            phase = self.fleet.phase if self.fleet else "starting"
            states = ", ".join(
                f"{rid}={v.status.state}:{100 * v.status.progress:.0f}%"
                + (f" ({v.gave_up} waypoints given up)" if v.gave_up else "")
                + (f" battery {100 * v.status.charge:.0f}%" if v.status.charge >= 0 else "")
                + (" charging" if v.status.charging else "")
                for rid, v in sorted(self.robots.items())
                if v.status is not None
            )
            lost = f" lost={','.join(self.fleet.lost)}" if self.fleet and self.fleet.lost else ""
            f = self.fleet
            tasks = (
                f" tasks {f.tasks_open} open, {f.tasks_assigned} assigned, {f.tasks_done} done"
                + (f", {f.tasks_left_out} left out" if f.tasks_left_out else "")
                if f
                else ""
            )
            dropped = dropped_text(self._dropped())
            return (
                f"[{wall_s:6.1f} s] {phase} sim={self.clock:.1f}s "
                f"coverage={100 * cov.coverage if cov else 0:.1f}%{tasks}{lost} {states}"
                + (f" dropped: {dropped}" if dropped else "")
            )


def dropped_text(dropped: Dropped) -> str:
    """``sim 3 implausible, robot-1 2 malformed``: the processes that dropped messages; "" if
    none did."""
    parts = []
    for name, (malformed, implausible) in dropped.items():
        counts = [f"{malformed} malformed"] if malformed else []
        counts += [f"{implausible} implausible"] if implausible else []
        if counts:
            parts.append(f"{name} {' '.join(counts)}")
    return ", ".join(parts)


def _event_text(e: FleetEvent) -> str:
    return _line(e.stamp, e.kind, e.robot, f"{e.task:<8} {e.detail}")


def _line(stamp: float, kind: str, robot: str, rest: str) -> str:
    """An event's text: sim time, kind, robot and the rest, in columns."""
    return f"sim {stamp:7.1f} s  {kind:<10} {robot:<10} {rest}".rstrip()


def _stamped(e: EventLine) -> str:
    return f"{time.strftime('%H:%M:%S', time.localtime(e.wall))} {e.text}"


# what BusFeed takes from ring buffers, newest per key only: topic under robot/<id>/, its
# message type and the model's method
_RING_STREAMS: tuple[tuple[str, type[Message], str], ...] = (
    ("truth", TruthPose, "on_truth"),
    ("intent", Intent, "on_intent"),
    ("status", RobotStatus, "on_status"),
)


class BusFeed:
    """Feeds a :class:`FleetWatcher` from a bus (see the module docstring). Call
    :meth:`pump` before each look at the model; :meth:`close` stops the fetch thread."""

    def __init__(self, bus: Bus, watcher: FleetWatcher, fetch: bool = True) -> None:
        import zenoh

        self.bus = bus
        self.watcher = watcher
        k = bus.keys
        w = watcher
        self._rings: list[tuple[Any, type[Message], Callable[[str, Any], None]]] = []
        for topic, cls, method in _RING_STREAMS:
            sub = bus.session.declare_subscriber(
                k.all_robots(topic), zenoh.handlers.RingChannel(RING_CAPACITY)
            )
            self._rings.append((sub, cls, getattr(w, method)))
        clock = bus.session.declare_subscriber(k.clock(), zenoh.handlers.RingChannel(64))
        self._rings.append((clock, Clock, w.on_clock))
        for key, cls, handler in (
            (k.coverage(), CoverageSummary, w.on_coverage),
            (k.coord_state(), FleetState, w.on_fleet),
            (k.collisions(), Collision, w.on_collision),
            (k.plan("*"), Plan, w.on_plan),
            (k.events(), FleetEvent, w.on_event),
            (k.all_robots("heartbeat"), Heartbeat, w.on_heartbeat),
        ):
            bus.subscribe(key, cls, self._counted(handler))
        bus.watch_alive(
            "agent", lambda rid: w.on_alive(rid, True), lambda rid: w.on_alive(rid, False)
        )
        self._stop = threading.Event()
        self._fetcher: threading.Thread | None = None
        if fetch:
            self._fetcher = threading.Thread(target=self._fetch_loop, name="dashboard-fetch")
            self._fetcher.daemon = True
            self._fetcher.start()

    def _counted(self, handler: Callable[[str, Any], None]) -> Callable[[str, Any], None]:
        rates = self.watcher.rates

        def on_message(key: str, msg: Any) -> None:
            rates.count(key)
            handler(key, msg)

        return on_message

    def pump(self) -> int:
        """Decode the newest sample per key of what the ring buffers hold into the model;
        returns how many samples came (all are counted in the rates)."""
        now = time.monotonic()
        seen = 0
        rates = self.watcher.rates
        for sub, cls, handler in self._rings:
            newest: dict[str, Any] = {}
            counts: dict[str, int] = {}
            while (sample := sub.try_recv()) is not None:
                key = str(sample.key_expr)
                newest[key] = sample
                counts[key] = counts.get(key, 0) + 1
            for key, n in counts.items():
                rates.count(key, n, now)
                seen += n
            for key, sample in newest.items():
                try:
                    msg = decode(sample.payload.to_bytes(), cls)
                except DecodeError as e:
                    self.bus.drop_malformed(key, e)
                    continue
                try:
                    handler(key, msg)
                except Exception:
                    log.exception("the view's handler for %s failed", key)
        self.watcher.set_own_dropped(self.bus.ident, *self.bus.dropped())
        return seen

    def fetch_once(self) -> None:
        """Ask for the floor plan (until it came; while the fleet explores, the merged map as
        it grows, every time) and the cleaned area, once each."""
        req = Request(f"dashboard-{self.bus.ident}")
        w = self.watcher
        if w.phase == EXPLORING:
            with contextlib.suppress(TimeoutError, RuntimeError, DecodeError):
                w.on_floor(
                    self.bus.request(self.bus.keys.explored_map(), req, MapPatches, FETCH_TIMEOUT_S)
                )
        elif w.floor is None:
            with contextlib.suppress(TimeoutError, RuntimeError, DecodeError):
                w.on_floor(
                    self.bus.request(self.bus.keys.floor_map(), req, MapPatches, FETCH_TIMEOUT_S)
                )
        with contextlib.suppress(TimeoutError, RuntimeError, DecodeError):
            w.on_cleaned(
                self.bus.request(
                    self.bus.keys.coverage_image(), req, CoverageImage, FETCH_TIMEOUT_S
                )
            )

    def _fetch_loop(self) -> None:
        while not self._stop.is_set():
            try:
                self.fetch_once()
            except Exception:
                log.exception("the dashboard could not fetch the floor plan or cleaned area")
            self._stop.wait(FETCH_PERIOD_S)

    def close(self) -> None:
        """Stop fetching; the subscriptions end with the bus."""
        self._stop.set()
        if self._fetcher is not None:
            self._fetcher.join(timeout=2 * FETCH_TIMEOUT_S + 1.0)
        for sub, *_ in self._rings:
            with contextlib.suppress(Exception):
                sub.undeclare()
