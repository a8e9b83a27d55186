"""What a receiver believes: the sim clock and a robot's positions move by what one step can
move them; a jump is believed only once messages in a row confirm it, and a jump never
confirmed is counted once a believable message supersedes it."""

from __future__ import annotations

from fleet.params import AgentParams, SimParams, load_fleet_config
from fleet.plausible import (
    CONFIRMATIONS,
    LAG_WALL_S,
    RATE_WINDOW_S,
    Bounds,
    PoseTrack,
    SimClock,
    Strangers,
    clock_step_s,
)

STEP = 0.5


class Drops:
    def __init__(self) -> None:
        self.calls: list[tuple[int, str]] = []

    def __call__(self, n: int, why: str) -> None:
        self.calls.append((n, why))

    @property
    def total(self) -> int:
        return sum(n for n, _ in self.calls)


def test_the_step_is_the_clock_period_or_the_agents_staleness_whichever_is_longer() -> None:
    assert clock_step_s(SimParams(clock_hz=20.0), AgentParams(stale_after_s=0.5)) == 0.5
    assert clock_step_s(SimParams(clock_hz=1.0), AgentParams(stale_after_s=0.5)) == 1.0
    cfg = load_fleet_config()
    b = Bounds.of(cfg)
    assert b.speed == cfg.robot.max_vel_x and b.margin_m == cfg.slam.search_window_xy


def test_a_lone_clock_stamp_far_ahead_never_moves_the_clock_and_is_counted() -> None:
    drops = Drops()
    clock = SimClock(STEP, drops)
    assert clock.hear(0.05) and clock.synced
    assert not clock.ahead(0.05 + STEP) and clock.ahead(1e9)
    assert not clock.hear(1e9) and clock.now == 0.05
    # the real clock goes on: the jump was implausible
    assert clock.hear(0.10) and clock.now == 0.10
    assert drops.calls and drops.total == 1 and "past the clock" in drops.calls[0][1]
    for t in (1e9, 2e9, 0.15, 1e9 + 1):
        clock.hear(t)
    assert clock.now == 0.15 and drops.total == 3


class Wall:
    """A wall clock the test moves."""

    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def _run(clock: SimClock, wall: Wall, rate: float, wall_s: float, hz: float = 20.0) -> None:
    """Clock messages at ``hz`` (sim) for ``wall_s`` wall seconds of a sim going ``rate`` × real
    time."""
    for _ in range(int(wall_s * hz * rate)):
        wall.t += 1.0 / (hz * rate)
        clock.hear(clock.now + 1.0 / hz)


def test_a_stamp_may_lead_the_clock_by_what_a_late_callback_makes_of_its_rate() -> None:
    """At 8 × real time a status handled before the clock messages sent ahead of it leads the
    clock by up to 8 × LAG_WALL_S of sim time: not implausible. At real time only a step is
    allowed; a stamp far ahead is implausible at any rate."""
    drops = Drops()
    wall = Wall()
    fast = SimClock(STEP, drops, wall=wall)
    fast.hear(0.0)
    _run(fast, wall, rate=8.0, wall_s=RATE_WINDOW_S)
    assert abs(fast.rate() - 8.0) < 0.1
    lead = 8.0 * LAG_WALL_S
    assert lead > 2 * STEP
    assert not fast.ahead(fast.now + lead - 0.1, strict=True)
    assert fast.ahead(fast.now + lead + 0.1, strict=True) and fast.ahead(1e9)
    slow = SimClock(STEP, drops, wall=wall)
    slow.hear(0.0)
    _run(slow, wall, rate=1.0, wall_s=RATE_WINDOW_S)
    assert abs(slow.rate() - 1.0) < 0.05
    assert not slow.ahead(slow.now + STEP - 0.01) and slow.ahead(slow.now + STEP + 0.1)
    assert drops.calls == []


def test_the_rate_is_the_recent_one_and_a_jump_is_not_a_rate() -> None:
    """The rate follows the last RATE_WINDOW_S of wall time (a sim that slows down allows less
    lead soon after), a receiver that has heard nothing for a while keeps the rate it last knew
    (it is the one running late), and a confirmed jump starts the window again."""
    wall = Wall()
    clock = SimClock(STEP, Drops(), wall=wall)
    clock.hear(0.0)
    _run(clock, wall, rate=8.0, wall_s=RATE_WINDOW_S)
    _run(clock, wall, rate=1.0, wall_s=2 * RATE_WINDOW_S)
    assert abs(clock.rate() - 1.0) < 0.05
    _run(clock, wall, rate=8.0, wall_s=RATE_WINDOW_S)
    wall.t += 30.0
    assert abs(clock.rate() - 8.0) < 0.1
    for k in range(CONFIRMATIONS):
        wall.t += 0.01
        clock.hear(clock.now + 500.0 + 0.05 * (k + 1))
    assert clock.rate() == 0.0


def test_a_late_or_resumed_clock_catches_up_once_messages_confirm_the_jump() -> None:
    drops = Drops()
    clock = SimClock(STEP, drops, now=100.0)
    assert not clock.synced and not clock.ahead(1e9)
    stamps = [130.0 + 0.05 * i for i in range(CONFIRMATIONS)]
    moved = [clock.hear(t) for t in stamps]
    assert moved == [False] * (CONFIRMATIONS - 1) + [True]
    assert clock.now == stamps[-1] and clock.synced and drops.calls == []
    # clock messages lost (up to a step's worth), or one overtaken by the next
    for t in (130.5, 130.95, 130.9, 131.3):
        clock.hear(t)
    assert clock.now == 131.3 and drops.calls == []
    # while a jump waits for confirmation, stamps up to it are not judged ahead
    clock.hear(231.3)
    assert clock.now == 131.3 and not clock.ahead(231.3) and clock.ahead(231.3 + 2 * STEP)
    assert clock.ahead(231.3, strict=True)  # strict: an unconfirmed jump does not count
    clock.hear(131.35)
    assert clock.ahead(231.3) and drops.total == 1


def test_a_forged_stamp_amid_a_jump_neither_spoils_nor_delays_its_confirmation() -> None:
    drops = Drops()
    clock = SimClock(STEP, drops, now=100.0)
    for t in (130.0, 1e9, 130.05, 2e9, 130.1):
        clock.hear(t)
    assert clock.now == 130.1 and drops.total == 2
    assert all("past the clock" in why for _, why in drops.calls)


def test_messages_that_agree_with_no_other_are_never_believed() -> None:
    drops = Drops()
    clock = SimClock(STEP, drops)
    clock.hear(0.0)
    for i in range(10):
        clock.hear(10.0 * (i + 1))
    assert clock.now == 0.0
    # the oldest chains beyond MAX_CHAINS are counted as they go, the rest when the clock moves
    clock.hear(0.05)
    assert clock.now == 0.05 and drops.total == 10


def test_a_pose_the_robot_cannot_have_driven_to_is_dropped_and_counted_once_superseded() -> None:
    drops = Drops()
    track = PoseTrack(0.5, 0.2, drops)
    assert track.hear(10.0, (1.0, 1.0))
    assert track.hear(11.0, (1.6, 1.0))  # 0.6 m in 1 s: within 0.5 m/s × 1 s + 0.2 m
    assert not track.hear(11.1, (500.0, 1.0))
    assert drops.calls == []
    assert track.hear(11.2, (1.65, 1.0))
    assert drops.total == 1 and "moved" in drops.calls[0][1]
    # older than the last believed: stale, neither believed nor counted
    assert not track.hear(5.0, (1.65, 1.0)) and drops.total == 1
    assert track.last == (11.2, (1.65, 1.0))


def test_a_real_jump_a_relocalization_is_believed_once_confirmed_and_not_counted() -> None:
    drops = Drops()
    track = PoseTrack(0.5, 0.2, drops)
    track.hear(0.0, (0.0, 0.0))
    heard = [track.hear(0.1 * i, (3.0 + 0.01 * i, 0.0)) for i in range(1, CONFIRMATIONS + 1)]
    assert heard == [False] * (CONFIRMATIONS - 1) + [True]
    assert track.last is not None and track.last[1][0] > 3.0 and drops.calls == []


def test_strangers_are_counted_only_when_no_token_comes_within_the_grace() -> None:
    """Messages from robots not in the job are held back per sender and key class: counted,
    with their number, once the grace has passed without the sender's token; forgotten when
    the token comes in time."""
    counted: list[tuple[str, str, int]] = []
    wall = Wall()

    def drop(key: str, sender: str, _why: str, n: int = 1) -> None:
        counted.append((key, sender, n))

    strangers = Strangers(5.0, drop, wall)
    for _ in range(3):
        strangers.heard("fleet/x/robot/robot-9/status", "robot-9", "not in the job")
    strangers.heard("fleet/x/robot/robot-9/pose", "robot-9", "not in the job")
    strangers.heard("fleet/x/robot/robot-2/status", "robot-2", "not in the job")
    wall.t += 4.9
    strangers.flush()
    assert counted == []
    strangers.joined("robot-2")
    wall.t += 0.2
    strangers.flush()
    assert sorted(counted) == [
        ("fleet/x/robot/robot-9/pose", "robot-9", 1),
        ("fleet/x/robot/robot-9/status", "robot-9", 3),
    ]
    strangers.flush()
    assert len(counted) == 2
