"""What an agent believes of the well-formed messages it takes, judged by what it knows.

The agent's sim clock is the simulator's, as :class:`fleet.plausible.SimClock` believes the
stamps of its clock messages and of the robot's scans: one message moves it a clock step at
most (the longer of 1 / ``sim.clock_hz`` and ``agent.stale_after_s``), a jump further only once
three agreeing messages confirm it. Nothing else moves it. Then, with the sender named:

- **odometry** stamped more than a clock step past the clock, or at a position its robot cannot
  have driven to since the last one believed (:class:`fleet.plausible.PoseTrack`; the first
  position too only once three agreeing ones confirm it), is dropped:
  the pose source keeps the newest odometry stamp, so one stamped far ahead would make it drop
  every real one as older;
- a **scan** stamped more than a clock step past the clock, or whose geometry (beam count, first
  angle, angle increment, range limits) is not the robot's lidar as configured, or with a range
  outside those limits, is dropped before it can take a real scan's place in the queue;
- a peer's **intent** from a robot not in the job (no liveliness token of it heard), stamped
  more than a clock step past the clock, whose points are not times from its stamp over the
  intent horizon, that moves faster than a robot can, or that puts the peer where it cannot have
  driven to since its last intent believed, is dropped: one stamped far ahead would stand in
  everyone's way for good;
- a **plan** of a kind the protocol does not name (``fleet.protocol.PLAN_KINDS``) is dropped:
  what it would have the robot do is unknown.

The agent does not take its peers' poses (their intents say where they are). The clock starts
at the sim time of the simulator's answer to the agent's spawn request (:meth:`start`); until
then nothing is judged by it and no odometry is tracked (the agent has no pose source yet and
takes none). Pure: no bus; the agent passes ``drop`` (:meth:`fleet.bus.Bus.drop_implausible`).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fleet.params import FleetConfig, LidarParams
from fleet.plausible import Bounds, PoseTrack, SimClock
from fleet.protocol import PLAN_KINDS, BatteryState, Intent, LaserScan, Odometry, Plan

# drop(key, sender, why, n): n messages on key from sender dropped as implausible
Drop = Callable[[str, str, str, int], None]

SIM = "sim"
COORDINATOR = "coordinator"
# a scan's angles and range limits are floats sent as such: equal within this
GEOMETRY_TOL = 1e-6


@dataclass(frozen=True)
class ScanShape:
    """The geometry of the robot's lidar as configured: what every real scan has."""

    beams: int
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float

    @classmethod
    def of(cls, lidar: LidarParams) -> ScanShape:
        """As the simulator's lidar casts it: ``beams`` over ``fov`` centred ahead."""
        return cls(
            lidar.beams, -lidar.fov / 2, lidar.fov / lidar.beams, lidar.range_min, lidar.range_max
        )

    def mismatch(self, scan: LaserScan) -> str:
        """Why ``scan`` is not one of this lidar's ("" if it is)."""
        if len(scan.ranges) != self.beams:
            return f"{len(scan.ranges)} beams, the lidar has {self.beams}"
        for name in ("angle_min", "angle_increment", "range_min", "range_max"):
            got, want = getattr(scan, name), getattr(self, name)
            if abs(got - want) > GEOMETRY_TOL:
                return f"{name} {got:.6g}, the lidar's is {want:.6g}"
        r = scan.ranges[np.isfinite(scan.ranges)]
        out = (r < self.range_min) | (r > self.range_max)
        if out.any():
            return f"{int(out.sum())} range(s) outside [{self.range_min:g}, {self.range_max:g}] m"
        return ""


class Receivers:
    """The agent's clock and its judgement of each message (see the module docstring).
    Thread-safe: Zenoh calls each subscriber on its own thread."""

    def __init__(
        self, rid: str, bounds: Bounds, shape: ScanShape, horizon_s: float, drop: Drop
    ) -> None:
        self.rid = rid
        self.bounds = bounds
        self.shape = shape
        self.horizon_s = horizon_s
        self._drop = drop
        self._clock_key = ""
        self.clock = SimClock(bounds.clock_step_s, self._clock_dropped)
        self.alive: set[str] = set()
        self._odometry: PoseTrack | None = None
        self._peers: dict[str, PoseTrack] = {}
        self._lock = threading.Lock()

    @classmethod
    def of(cls, rid: str, cfg: FleetConfig, drop: Drop) -> Receivers:
        return cls(rid, Bounds.of(cfg), ScanShape.of(cfg.lidar), cfg.agent.intent_horizon_s, drop)

    @property
    def now(self) -> float:
        """The sim time the agent believes."""
        return self.clock.now

    def _clock_dropped(self, n: int, why: str) -> None:
        self._drop(self._clock_key, SIM, why, n)

    def _ahead(self, stamp: float) -> str:
        # strict: a forged clock message waiting for confirmation must not let a message
        # forged with its stamp through; a real jump is confirmed within three clock messages
        if not self.clock.ahead(stamp, strict=True):
            return ""
        return f"stamped {stamp:.3f} s, past the sim clock at {self.clock.now:.3f} s"

    def _judge(self, key: str, sender: str, why: str) -> bool:
        """Drop with ``why`` unless it is empty; whether the message is believed."""
        if why:
            self._drop(key, sender, why, 1)
        return not why

    def start(self, now: float) -> None:
        """The simulator answered the spawn request at sim time ``now``: the clock is there."""
        self.clock.start(now)

    def on_clock(self, key: str, stamp: float) -> None:
        """A clock message from the simulator."""
        self._clock_key = key
        self.clock.hear(stamp)

    def joined(self, rid: str) -> None:
        with self._lock:
            self.alive.add(rid)

    def left(self, rid: str) -> None:
        with self._lock:
            self.alive.discard(rid)

    def odometry(self, key: str, msg: Odometry) -> bool:
        """Whether to believe the robot's odometry ``msg``."""
        if not self._judge(key, SIM, self._ahead(msg.stamp)):
            return False
        if not self.clock.synced:
            return True
        with self._lock:
            if self._odometry is None:
                self._odometry = self._track(key, SIM)
            return self._odometry.hear(msg.stamp, (msg.x, msg.y))

    def battery(self, key: str, msg: BatteryState) -> bool:
        """Whether to believe the robot's battery reading ``msg``: a fraction of a full charge,
        stamped no later than the clock allows."""
        why = "" if 0.0 <= msg.percentage <= 1.0 else f"charge {msg.percentage:.3g} not in 0..1"
        return self._judge(key, SIM, why or self._ahead(msg.stamp))

    def plan(self, key: str, msg: Plan) -> bool:
        """Whether to take the coordinator's plan ``msg``: of a kind the protocol names."""
        why = "" if msg.kind in PLAN_KINDS else f"plan kind {msg.kind!r} not one of {PLAN_KINDS}"
        return self._judge(key, COORDINATOR, why)

    def scan(self, key: str, msg: LaserScan) -> bool:
        """Whether to believe the robot's scan ``msg``; a believed one is heard by the clock."""
        if not self._judge(key, SIM, self.shape.mismatch(msg) or self._ahead(msg.stamp)):
            return False
        self._clock_key = self._clock_key or key
        self.clock.hear(msg.stamp)
        return True

    def intent(self, key: str, peer: str, msg: Intent) -> bool:
        """Whether to believe ``peer``'s intent ``msg``."""
        with self._lock:
            known = peer in self.alive
        why = "" if known else "not in the job: no liveliness token of it heard"
        if not self._judge(key, peer, why or self._ahead(msg.stamp) or self._intent_shape(msg)):
            return False
        if not len(msg.points):
            return True
        with self._lock:
            track = self._peers.get(peer)
            if track is None:
                track = self._peers[peer] = self._track(key, peer)
            t, x, y = msg.points[0]
            return track.hear(float(t), (float(x), float(y)))

    def _intent_shape(self, msg: Intent) -> str:
        """Why the points of an intent are none a robot can announce ("" if they can be)."""
        pts = msg.points
        if not len(pts):
            return ""
        t = pts[:, 0]
        step = self.bounds.clock_step_s
        if t[0] < msg.stamp - step or t[-1] > msg.stamp + self.horizon_s + step:
            return (
                f"its points run {t[0]:.3f}-{t[-1]:.3f} s, not within the "
                f"{self.horizon_s:g} s after its stamp {msg.stamp:.3f} s"
            )
        dt = np.diff(t)
        if (dt < 0).any():
            return "its points go back in time"
        gaps = np.hypot(*np.diff(pts[:, 1:], axis=0).T)
        reach = self.bounds.speed * dt + self.bounds.margin_m
        if (gaps > reach).any():
            k = int(np.argmax(gaps - reach))
            return f"its points move {gaps[k]:.2f} m in {dt[k]:.3f} s, farther than a robot drives"
        return ""

    def _track(self, key: str, sender: str) -> PoseTrack:
        """A robot's positions as believed here; the first too only once confirmed: a forged
        first one would be held against every real one."""
        return PoseTrack(
            self.bounds.speed,
            self.bounds.margin_m,
            lambda n, why: self._drop(key, sender, why, n),
            confirm_first=True,
        )
