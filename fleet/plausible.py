"""What a receiver may believe of a well-formed message, judged by what it already knows.

A stamp far ahead of the receiver's sim clock, or a pose farther from the robot's last one than
the robot can drive, is dropped and counted (:meth:`fleet.bus.Bus.drop_implausible`) like a
malformed payload. No single message moves a clock or a position by more than one step could:

- :class:`SimClock` follows the simulator's clock messages. One at most ``step_s`` past the
  clock moves it; one farther ahead is believed only once ``CONFIRMATIONS`` such messages, each
  within ``step_s`` of the others, say that time has moved on that far (a receiver that started
  late, was stopped for a while or lost clock messages catches up within a few messages; a lone
  stamp far ahead never moves it, nor does it keep the real clock's jump from being believed).
  Other messages' stamps may lead it by a step, or by what a loaded receiver's late callbacks
  make of the clock's rate (:meth:`SimClock.ahead`).
- :class:`PoseTrack` follows one robot's reported positions the same way: a position the robot
  can have driven to since the last one believed (``speed`` × the time between their stamps +
  ``margin_m``) is believed; a jump is believed once ``CONFIRMATIONS`` positions, each within
  reach of the one before, agree with it (a re-localized robot, a SLAM correction).

Messages not believed yet wait in chains of messages that agree with each other (at most
``MAX_CHAINS``). A chain never confirmed is reported to ``dropped``, with how many messages it
held, once a believable message or a confirmed chain supersedes it, so what is counted is what
was really implausible.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from fleet.params import AgentParams, FleetConfig, SimParams
from fleet.protocol import Clock, key_class

# a jump is believed once this many messages agree with it: one is never enough
CONFIRMATIONS = 3
# chains of messages not believed yet that a receiver keeps; the oldest beyond goes
MAX_CHAINS = 4

# a receiver's callbacks may run this long (wall s) behind the messages it was sent, on a
# loaded machine: a stamp may lead its clock by the sim time this much wall time holds
LAG_WALL_S = 0.5
# the sim clock's rate is judged over its moves in this much wall time (s) ...
RATE_WINDOW_S = 2.0
# ... once they span at least this much
MIN_RATE_SPAN_S = 0.2

# dropped(n, why): n messages were dropped as implausible, for this reason
Dropped = Callable[[int, str], None]


def clock_step_s(sim: SimParams, agent: AgentParams) -> float:
    """How far one message may move a receiver's sim clock, and how far ahead of it a robot's
    stamp may be: a receiver's copy of the clock lags the simulator's by a clock period
    (1 / ``sim.clock_hz``) when no clock message is lost, and a robot acts on its newest data
    for at most ``agent.stale_after_s`` before it stops. A stamp farther ahead was not stamped
    by this simulator's clock."""
    return max(1.0 / sim.clock_hz, agent.stale_after_s)


@dataclass(frozen=True)
class Bounds:
    """What one message may move: the sim clock by ``clock_step_s``; a robot's position by
    ``speed`` (its top speed, m/s) × the sim time since its last one, + ``margin_m``."""

    clock_step_s: float
    speed: float
    margin_m: float

    @classmethod
    def of(cls, cfg: FleetConfig) -> Bounds:
        """From the fleet's parameters: the margin is the farthest the SLAM tracking moves a
        pose from its odometry prediction in one scan (``slam.search_window_xy``)."""
        return cls(clock_step_s(cfg.sim, cfg.agent), cfg.robot.max_vel_x, cfg.slam.search_window_xy)


@dataclass
class _Jump:
    """Messages that agree with each other and that the receiver does not believe yet: the
    newest one's stamp (and position), how many, and why the first was not believed."""

    stamp: float
    xy: tuple[float, float] | None
    count: int
    why: str


class _Jumps:
    """The chains of messages not believed yet (see the module docstring)."""

    def __init__(self, dropped: Dropped) -> None:
        self.dropped = dropped
        self.chains: list[_Jump] = []

    def hear(self, jump: _Jump, agrees: Callable[[_Jump], bool]) -> _Jump | None:
        """Add one message (``jump``, count 1) to the first chain it ``agrees`` with, or start
        a chain with it; the chain it confirmed (the others then settled), else None."""
        for chain in self.chains:
            if agrees(chain):
                chain.stamp = max(chain.stamp, jump.stamp)
                chain.xy = jump.xy
                chain.count += 1
                if chain.count < CONFIRMATIONS:
                    return None
                self.chains.remove(chain)
                self.settle()
                return chain
        self.chains.append(jump)
        if len(self.chains) > MAX_CHAINS:
            oldest = self.chains.pop(0)
            self.dropped(oldest.count, oldest.why)
        return None

    def settle(self) -> None:
        """A believable message came: the chains before it, never confirmed, were
        implausible."""
        for chain in self.chains:
            self.dropped(chain.count, chain.why)
        self.chains.clear()

    def newest(self) -> float | None:
        """The newest stamp of a chain that may be confirmed next."""
        return max((c.stamp for c in self.chains), default=None)


class SimClock:
    """The newest sim time a receiver believes the simulator's clock messages (see the module
    docstring); ``synced`` once it has believed one since it started. Thread-safe.

    It also knows how fast sim time has been going (:meth:`rate`, sim seconds per wall second
    over the last ``RATE_WINDOW_S`` of clock messages it believed, taken at the wall time
    ``wall`` returns). A starved receiver runs its callbacks late and not in the order the
    messages were sent: a robot's status can be handled before the clock messages sent before
    it, by as much sim time as passes in ``LAG_WALL_S`` of wall time, several steps when the
    simulator runs faster than real time (``--speed 0``). :meth:`ahead` allows that lead."""

    def __init__(
        self,
        step_s: float,
        dropped: Dropped,
        now: float = 0.0,
        wall: Callable[[], float] = time.monotonic,
    ) -> None:
        self.step_s = step_s
        self.now = now
        self.synced = False
        self._jumps = _Jumps(dropped)
        self._lock = threading.Lock()
        self._wall = wall
        self._moves: deque[tuple[float, float]] = deque()

    def start(self, now: float) -> None:
        """Believe ``now``, told by the simulator itself (its answer to a query, not a message
        anyone may publish): the clock is synced there, and what waits for confirmation goes."""
        with self._lock:
            self._jumps.chains.clear()
            self.now, self.synced = now, True

    def hear(self, stamp: float) -> bool:
        """Take one clock message; whether it moved the clock."""
        with self._lock:
            if stamp <= self.now + self.step_s:
                self._jumps.settle()
                self.synced = True
                moved = stamp > self.now
                self.now = max(self.now, stamp)
                if moved:
                    self._moved()
                return moved
            why = f"sim time {stamp:.3f} s, {stamp - self.now:.3f} s past the clock"
            confirmed = self._jumps.hear(
                _Jump(stamp, None, 1, why), lambda c: abs(stamp - c.stamp) <= self.step_s
            )
            if confirmed is None:
                return False
            self.now, self.synced = confirmed.stamp, True
            self._moves.clear()
            return True

    def _moved(self) -> None:
        """Note the clock's move to ``now`` (the lock held) for :meth:`rate`."""
        wall = self._wall()
        self._moves.append((wall, self.now))
        while self._moves and self._moves[0][0] < wall - RATE_WINDOW_S:
            self._moves.popleft()

    def rate(self) -> float:
        """Sim seconds per wall second over the clock's moves in the last ``RATE_WINDOW_S``
        before its newest one (0 until they span ``MIN_RATE_SPAN_S``). A confirmed jump is not
        a rate: the window starts again after it."""
        with self._lock:
            return self._rate()

    def _rate(self) -> float:
        if len(self._moves) < 2:
            return 0.0
        (w0, t0), (w1, t1) = self._moves[0], self._moves[-1]
        return (t1 - t0) / (w1 - w0) if w1 - w0 >= MIN_RATE_SPAN_S else 0.0

    def ahead(self, stamp: float, strict: bool = False) -> bool:
        """Whether ``stamp`` is farther ahead of the clock than any robot's can be: more than a
        step past it (or than ``LAG_WALL_S`` of wall time holds at the clock's :meth:`rate`,
        whichever is more), and past a jump it may be about to confirm (a receiver catching up
        after a stop) unless ``strict``: then a jump not confirmed yet does not count (a forged
        clock message would let a message forged with the same stamp through). Never before the
        clock has synced: until then it knows no time to judge by."""
        with self._lock:
            pending = None if strict else self._jumps.newest()
            limit = self.now if pending is None else max(self.now, pending)
            lead = max(self.step_s, self._rate() * LAG_WALL_S)
            return self.synced and stamp > limit + lead


class PoseTrack:
    """One robot's positions as a receiver believes them (see the module docstring). With
    ``confirm_first`` the first position too is believed only once ``CONFIRMATIONS`` agreeing
    ones confirm it (a receiver that would otherwise hold a forged first one against the real
    ones). Not thread-safe: the receiver holds its own lock."""

    def __init__(
        self, speed: float, margin_m: float, dropped: Dropped, confirm_first: bool = False
    ) -> None:
        self.speed = speed
        self.margin_m = margin_m
        self.last: tuple[float, tuple[float, float]] | None = None
        self.confirm_first = confirm_first
        self._jumps = _Jumps(dropped)

    def hear(self, stamp: float, xy: tuple[float, float]) -> bool:
        """Take one position reported at sim time ``stamp``; whether it is believed. One older
        than the last believed is dropped as stale, not counted."""
        if self.last is None:
            if self.confirm_first:
                return self._confirm(stamp, xy, "not confirmed by a second position yet")
            self.last = (stamp, xy)
            return True
        t0, xy0 = self.last
        if stamp < t0:
            return False
        why = self._out_of_reach(t0, xy0, stamp, xy)
        if why is None:
            self._jumps.settle()
            self.last = (stamp, xy)
            return True
        return self._confirm(stamp, xy, why)

    def _confirm(self, stamp: float, xy: tuple[float, float], why: str) -> bool:
        """A position not believable yet: whether it confirms a chain of agreeing ones."""
        confirmed = self._jumps.hear(
            _Jump(stamp, xy, 1, why),
            lambda c: c.xy is not None and self._out_of_reach(c.stamp, c.xy, stamp, xy) is None,
        )
        if confirmed is None:
            return False
        self.last = (stamp, xy)
        return True

    def _out_of_reach(
        self, t0: float, xy0: tuple[float, float], stamp: float, xy: tuple[float, float]
    ) -> str | None:
        """Why ``xy`` at ``stamp`` is out of the robot's reach from ``xy0`` at ``t0``; None if
        it is within."""
        gap = math.dist(xy0, xy)
        reach = self.speed * max(stamp - t0, 0.0) + self.margin_m
        if stamp >= t0 and gap <= reach:
            return None
        return f"moved {gap:.2f} m in {stamp - t0:.3f} s sim, farther than {reach:.2f} m"


# drop(key, sender, why, n): a receiver drops n messages on ``key`` from ``sender`` as
# implausible (:meth:`fleet.bus.Bus.drop_implausible`)
Drop = Callable[..., None]


# a robot's token is awaited this long (wall s) after its first message before what it sent is
# counted as implausible: on a loaded machine a token can come a second or more after them
STRANGER_GRACE_S = 5.0


class Strangers:
    """Messages from robots not in the job. Each is dropped at once, but a robot's first
    messages can reach a loaded receiver before its liveliness token does (they come on other
    keys, handled by other threads): they are counted as implausible through ``drop`` only
    when no token of their sender has come ``grace_s`` (wall seconds, at the time ``wall``
    returns) after the first of them (:meth:`flush`). Thread-safe."""

    def __init__(self, grace_s: float, drop: Drop, wall: Callable[[], float] = time.monotonic):
        self.grace_s = grace_s
        self.drop = drop
        self._wall = wall
        self._held: dict[tuple[str, str], _Held] = {}
        self._lock = threading.Lock()

    def heard(self, key: str, sender: str, why: str) -> None:
        """A message on ``key`` from ``sender``, not in the job, was dropped for ``why``."""
        with self._lock:
            held = self._held.setdefault((sender, key_class(key)), _Held(self._wall(), key, why))
            held.count += 1
        self.flush()

    def joined(self, sender: str) -> None:
        """``sender``'s token came: what it sent before was early, not implausible."""
        with self._lock:
            for k in [k for k in self._held if k[0] == sender]:
                del self._held[k]

    def flush(self) -> None:
        """Count the messages of senders whose token has not come within the grace."""
        now = self._wall()
        with self._lock:
            due = [(k, v) for k, v in self._held.items() if now - v.first >= self.grace_s]
            for k, _ in due:
                del self._held[k]
        for (sender, _), held in due:
            self.drop(held.key, sender, held.why, held.count)


@dataclass
class _Held:
    """Messages of one sender on one key class held back by :class:`Strangers`: when the
    first came (wall s), one of their keys, why they were dropped, and how many."""

    first: float
    key: str
    why: str
    count: int = 0


class StampWatch:
    """The judge of a receiver that only watches the fleet (the live view, the run's recorder):
    its own :class:`SimClock`, fed every clock message (``hear_clock``), and messages stamped
    farther past it than any robot's can be, dropped through ``drop`` (``ahead``). Such a
    message would otherwise stand as a robot's newest status or pose, or the newest coverage,
    and hide every real one after it. It also knows the robots in the job (``join``: their
    liveliness tokens heard, as the coordinator and the agents know them) and drops what a robot
    not among them sends (``stranger``), which would otherwise stand as a robot of the fleet.
    Thread-safe.
    """

    def __init__(self, step_s: float, drop: Drop, clock_key: str) -> None:
        self.drop = drop
        self.clock = SimClock(step_s, lambda n, why: drop(clock_key, "sim", why, n))
        self.strangers = Strangers(STRANGER_GRACE_S, drop)
        self._members: set[str] = set()
        self._lock = threading.Lock()

    def join(self, rid: str) -> None:
        """Robot ``rid`` is in the job: its liveliness token was heard (it stays in the job
        once its token goes)."""
        with self._lock:
            self._members.add(rid)
        self.strangers.joined(rid)

    def stranger(self, key: str, sender: str) -> bool:
        """Whether to drop the message on ``key`` from robot ``sender``: it is not in the job
        (see :meth:`join`); then it is counted unless the sender's token comes soon after
        (:class:`Strangers`)."""
        with self._lock:
            known = sender in self._members
        if known:
            return False
        self.strangers.heard(key, sender, "not in the job: no liveliness token of it heard")
        return True

    def hear_clock(self, _key: str, msg: Clock) -> None:
        self.clock.hear(msg.stamp)

    def ahead(self, key: str, sender: str, stamp: float) -> bool:
        """Whether to drop the message on ``key`` from ``sender`` stamped ``stamp``: it is
        stamped past the clock (see :meth:`SimClock.ahead`, strict); then it is counted. Before
        the clock has synced every stamped message is dropped, uncounted: there is no time to
        judge it by yet (a view started while a rogue sends would hold its status stamped
        1e9 s as a robot's newest, and hide every real one after it)."""
        if not self.clock.synced:
            return True
        if not self.clock.ahead(stamp, strict=True):
            return False
        why = f"stamped {stamp:.3f} s, past the sim clock at {self.clock.now:.3f} s"
        self.drop(key, sender, why)
        return True
