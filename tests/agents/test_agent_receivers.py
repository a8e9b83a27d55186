"""The agent's receivers without a bus: its clock moves a step at a time, odometry and scans
stamped past it or not from its lidar are dropped and counted, intents no peer in the job can
send are dropped; and the agent's shell, on a stand-in bus, keeps real odometry after a forged
one and answers a scan whose control step raises with a stop instead of dying."""

from __future__ import annotations

import math
import threading
import time
from collections import Counter
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from agents.agent import Agent
from agents.peers import path_intent
from agents.receivers import Receivers, ScanShape
from fleet.params import load_fleet_config
from fleet.plausible import Bounds
from fleet.protocol import (
    BatteryState,
    Clock,
    Intent,
    Keys,
    LaserScan,
    Message,
    Odometry,
    Plan,
    SpawnReply,
    Twist,
)

CFG = load_fleet_config()
STEP = Bounds.of(CFG).clock_step_s
KEYS = Keys("t")
ODOM = KEYS.robot("robot-1", "odom")
SCAN = KEYS.robot("robot-1", "scan")
INTENT = KEYS.robot("robot-0", "intent")
BATTERY = KEYS.robot("robot-1", "battery")


class Drops:
    """What a receiver dropped: (key, sender, why, n) rows."""

    def __init__(self) -> None:
        self.rows: list[tuple[str, str, str, int]] = []

    def __call__(self, key: str, sender: str, why: str, n: int) -> None:
        self.rows.append((key, sender, why, n))

    @property
    def count(self) -> int:
        return sum(r[3] for r in self.rows)


def _rx() -> tuple[Receivers, Drops]:
    drops = Drops()
    rx = Receivers.of("robot-1", CFG, drops)
    for stamp in (9.9, 9.95, 10.0):  # three agreeing clock messages: the clock is at 10 s
        rx.on_clock(KEYS.clock(), stamp)
    assert rx.now == 10.0 and rx.clock.synced
    return rx, drops


def _odom(stamp: float, x: float = 1.0) -> Odometry:
    return Odometry(stamp, x, 2.0, 0.0, 0.0, 0.0)


def _scan(stamp: float, **change: Any) -> LaserScan:
    shape = ScanShape.of(CFG.lidar)
    fields = {
        "angle_min": shape.angle_min,
        "angle_increment": shape.angle_increment,
        "range_min": shape.range_min,
        "range_max": shape.range_max,
        "ranges": np.full(shape.beams, 2.0, dtype=np.float32),
    }
    fields.update(change)
    return LaserScan(stamp, **fields)


def _first_odometry(rx: Receivers, until: float = 10.0) -> None:
    """The robot's first odometry: believed once the third agreeing one confirms it."""
    assert not rx.odometry(ODOM, _odom(until - 0.04))
    assert not rx.odometry(ODOM, _odom(until - 0.02))
    assert rx.odometry(ODOM, _odom(until))


def _intent(stamp: float, x: float = 1.0) -> Intent:
    points = path_intent(np.array([x, 1.0]), np.array([[x + 1.0, 1.0]]), 0.3, stamp, 2.0)
    return Intent(stamp, points, 4, 2)


def test_a_clock_message_far_ahead_does_not_move_the_clock_and_scans_do_a_step_at_a_time() -> None:
    rx, drops = _rx()
    rx.on_clock(KEYS.clock(), 1e9)
    assert rx.now == 10.0
    assert rx.scan(SCAN, _scan(10.1)) and rx.now == 10.1
    rx.on_clock(KEYS.clock(), 10.15)  # a real clock message settles the forged one: counted
    assert rx.now == 10.15 and drops.rows == [(KEYS.clock(), "sim", drops.rows[0][2], 1)]


def test_odometry_stamped_far_ahead_is_dropped_and_real_odometry_still_believed() -> None:
    rx, drops = _rx()
    _first_odometry(rx)
    assert not rx.odometry(ODOM, _odom(1e9))
    assert drops.rows[0][:2] == (ODOM, "sim") and "past the sim clock" in drops.rows[0][2]
    # the pose source behind the receiver never sees it: the next real odometry is newer
    assert rx.odometry(ODOM, _odom(10.02, 1.005))
    assert not rx.odometry(ODOM, _odom(10.0 + STEP + 0.01))
    assert drops.count == 2


def test_a_forged_clock_message_does_not_let_odometry_forged_with_its_stamp_through() -> None:
    rx, drops = _rx()
    _first_odometry(rx)
    rx.on_clock(KEYS.clock(), 1e9)  # waits for confirmation; it must not widen the bound
    assert not rx.odometry(ODOM, _odom(1e9 + 0.01, 0.0))
    assert rx.odometry(ODOM, _odom(10.02))
    assert drops.rows[-1][:2] == (ODOM, "sim") and "past the sim clock" in drops.rows[-1][2]


def test_odometry_the_robot_cannot_have_driven_to_is_dropped() -> None:
    rx, drops = _rx()
    _first_odometry(rx)
    assert not rx.odometry(ODOM, _odom(10.02, 4.0))
    assert rx.odometry(ODOM, _odom(10.04, 1.01))
    assert drops.count == 1 and "farther than" in drops.rows[0][2]


def test_a_forged_first_odometry_is_not_held_against_the_real_ones() -> None:
    rx, drops = _rx()
    assert not rx.odometry(ODOM, _odom(9.95, 40.0))
    _first_odometry(rx)
    assert drops.count == 1 and drops.rows[0][:2] == (ODOM, "sim")


@pytest.mark.parametrize(
    ("change", "why"),
    [
        ({"ranges": np.full(180, 2.0, dtype=np.float32)}, "180 beams"),
        ({"angle_min": 0.0}, "angle_min"),
        ({"angle_increment": 0.02}, "angle_increment"),
        ({"range_max": 60.0}, "range_max"),
        ({"range_min": 0.0}, "range_min"),
        ({"ranges": np.full(360, 40.0, dtype=np.float32)}, "outside"),
    ],
)
def test_a_scan_not_from_the_robots_lidar_is_dropped(change: dict, why: str) -> None:
    rx, drops = _rx()
    assert not rx.scan(SCAN, _scan(10.1, **change))
    assert drops.count == 1 and why in drops.rows[0][2] and drops.rows[0][1] == "sim"
    assert rx.now == 10.0
    assert rx.scan(SCAN, _scan(10.1))


def test_a_battery_reading_beyond_a_full_charge_or_stamped_ahead_is_dropped() -> None:
    rx, drops = _rx()
    assert rx.battery(BATTERY, BatteryState(10.0, 0.5, False))
    assert not rx.battery(BATTERY, BatteryState(10.0, 1.5, False))
    assert not rx.battery(BATTERY, BatteryState(60.0, 0.5, False))
    assert drops.count == 2


def test_a_plan_of_a_kind_the_protocol_does_not_name_is_dropped() -> None:
    rx, drops = _rx()
    plan = Plan(10.0, 3, "t00", np.array([[0.0, 0.0], [1.0, 0.0]]))
    assert rx.plan(KEYS.plan("robot-1"), plan)
    assert rx.plan(KEYS.plan("robot-1"), replace(plan, kind="dock"))
    assert not rx.plan(KEYS.plan("robot-1"), replace(plan, kind="banana"))
    assert [(r[1], r[3]) for r in drops.rows] == [("coordinator", 1)]


def test_a_scan_stamped_far_ahead_is_dropped() -> None:
    rx, drops = _rx()
    assert not rx.scan(SCAN, _scan(1e9))
    assert drops.count == 1 and rx.now == 10.0


def test_before_the_clock_is_heard_nothing_is_judged_by_it() -> None:
    """A respawned agent starts at 0 while the sim is far on: its first scans are answered."""
    drops = Drops()
    rx = Receivers.of("robot-1", CFG, drops)
    for i in range(3):
        assert rx.scan(SCAN, _scan(300.0 + 0.1 * i))
    assert rx.now == pytest.approx(300.2) and drops.count == 0


def test_the_clock_starts_at_the_spawn_reply_and_odometry_before_it_is_not_tracked() -> None:
    """Odometry forged far ahead before the agent knows the time is not held against the real
    odometry that follows once the simulator's answer has set its clock."""
    drops = Drops()
    rx = Receivers.of("robot-1", CFG, drops)
    assert rx.odometry(ODOM, _odom(1e9, 5.0))  # not judged: the agent knows no time yet
    rx.start(10.0)
    assert rx.clock.synced and rx.now == 10.0
    _first_odometry(rx, 10.04)
    assert not rx.odometry(ODOM, _odom(1e9, 5.0)) and drops.count == 1


def test_intents_of_a_robot_not_in_the_job_or_stamped_ahead_are_dropped() -> None:
    rx, drops = _rx()
    assert not rx.intent(INTENT, "robot-0", _intent(10.0))
    assert "not in the job" in drops.rows[-1][2] and drops.rows[-1][1] == "robot-0"
    rx.joined("robot-0")
    # the first position of a peer is believed once three agreeing intents confirm it
    assert not rx.intent(INTENT, "robot-0", _intent(9.8))
    assert not rx.intent(INTENT, "robot-0", _intent(9.9))
    assert rx.intent(INTENT, "robot-0", _intent(10.0))
    assert not rx.intent(INTENT, "robot-0", _intent(1e9))
    assert "past the sim clock" in drops.rows[-1][2]
    rx.left("robot-0")
    assert not rx.intent(INTENT, "robot-0", _intent(10.1))
    assert drops.count == 3


def test_intents_no_robot_announces_are_dropped() -> None:
    rx, drops = _rx()
    rx.joined("robot-0")
    # the first position of a peer is believed once three agreeing intents confirm it
    assert not rx.intent(INTENT, "robot-0", _intent(9.8))
    assert not rx.intent(INTENT, "robot-0", _intent(9.9))
    assert rx.intent(INTENT, "robot-0", _intent(10.0))
    late = _intent(10.1)
    # points 100 s after the stamp: it would stand in everyone's way for good
    far = Intent(10.1, late.points + np.array([100.0, 0.0, 0.0]), 4, 2)
    assert not rx.intent(INTENT, "robot-0", far)
    fast = late.points.copy()
    fast[-1, 1] += 5.0
    assert not rx.intent(INTENT, "robot-0", Intent(10.1, fast, 4, 2))
    # a jump of the peer itself, farther than it drives in 0.1 s
    assert not rx.intent(INTENT, "robot-0", _intent(10.1, x=4.0))
    assert rx.intent(INTENT, "robot-0", _intent(10.1, x=1.03))
    assert drops.count == 3


# ---- the shell, on a stand-in bus ---------------------------------------------------------


class StandInBus:
    """What the agent's shell uses of :class:`fleet.bus.Bus`, recording what it publishes."""

    def __init__(self) -> None:
        self.keys = KEYS
        self.ident = "robot-1"
        self.published: list[tuple[str, Message]] = []
        self.decode_errors: Counter[str] = Counter()
        self.implausible: Counter[str] = Counter()
        self.handler_errors: Counter[str] = Counter()

    def publish(self, key: str, msg: Message, control: bool = False) -> None:
        self.published.append((key, msg))

    def request(self, key: str, msg: Message, reply_cls: type, timeout: float = 5.0) -> Message:
        if key == KEYS.sim_spawn():
            return SpawnReply(True, "", 1.0, 2.0, 0.0, 10.0)
        raise TimeoutError(f"{key}: nothing serves it here")

    def subscribe(self, *_args: object) -> None:
        return None

    serve = watch_alive = subscribe

    def drop_implausible(self, key: str, sender: str, why: str, n: int = 1) -> None:
        self.implausible[key] += n

    def handler_failed(self, kind: str) -> None:
        self.handler_errors[kind] += 1

    def dropped(self) -> tuple[int, int]:
        return sum(self.decode_errors.values()), sum(self.implausible.values())


def _agent(tmp_path: Path) -> tuple[Agent, StandInBus]:
    """An agent spawned by the simulator's answer at sim time 10 s, on odometry."""
    bus = StandInBus()
    cfg = replace(CFG, agent=replace(CFG.agent, pose_source="odometry"))
    agent = Agent(bus, "robot-1", cfg, tmp_path)  # type: ignore[arg-type]
    agent.spawn((1.0, 2.0, 0.0))
    assert agent.clock == 10.0
    return agent, bus


def test_the_agent_keeps_its_odometry_after_a_forged_one(tmp_path: Path) -> None:
    agent, bus = _agent(tmp_path)
    for stamp in (9.96, 9.98, 10.0):
        agent._on_odom(ODOM, _odom(stamp))
    agent._on_odom(ODOM, Odometry(1e9, 9.0, 9.0, 0.0, 5.0, 0.0))
    agent._on_odom(ODOM, _odom(10.02, 1.005))
    agent._on_clock(KEYS.clock(), Clock(1e9, 0.0, False))
    assert agent.odom_stamp == 10.02 and agent.pose_source.pose() == (1.005, 2.0, 0.0)
    assert sum(bus.implausible.values()) == 1 and agent.clock == 10.0


def test_a_scan_whose_step_raises_is_answered_with_a_stop_and_counted(tmp_path: Path) -> None:
    agent, bus = _agent(tmp_path)

    def broken(scan: LaserScan) -> Twist:
        raise RuntimeError("a bug in the control step")

    agent.step = broken  # type: ignore[method-assign]
    agent._on_scan(SCAN, _scan(10.1))
    agent._on_scan(SCAN, _scan(1e9))  # dropped: it would take the real scan's place
    runner = threading.Thread(target=agent.run, daemon=True)
    runner.start()
    try:
        deadline = 50
        while not bus.handler_errors and deadline:
            threading.Event().wait(0.05)
            deadline -= 1
    finally:
        agent.stop.set()
        runner.join(5.0)
    assert bus.handler_errors == Counter({"robot/*/scan": 1})
    stops = [m for k, m in bus.published if k.endswith("cmd_vel")]
    assert len(stops) == 1 and isinstance(stops[0], Twist)
    assert (stops[0].stamp, stops[0].v, stops[0].w) == (10.1, 0.0, 0.0)
    assert math.isclose(sum(bus.implausible.values()), 1)


class ClosingBus(StandInBus):
    """A stand-in bus whose heartbeats take a while to send, closed by the test as the agent's
    process closes its bus once ``Agent.run`` returns: what is sent after raises."""

    def __init__(self) -> None:
        super().__init__()
        self.closed = False
        self.sending_heartbeat = threading.Event()

    def publish(self, key: str, msg: Message, control: bool = False) -> None:
        if key.endswith("heartbeat"):
            self.sending_heartbeat.set()
            time.sleep(0.3)
        if self.closed:
            raise RuntimeError("session closed")
        super().publish(key, msg, control)


def test_the_agent_returns_from_run_only_once_its_heartbeats_have_ended(tmp_path: Path) -> None:
    """A heartbeat on its way when the agent stopped was sent after its process had closed the
    bus: a traceback in the agent's log at the end of a chaos run."""
    bus = ClosingBus()
    cfg = replace(CFG, agent=replace(CFG.agent, pose_source="odometry"))
    agent = Agent(bus, "robot-1", cfg, tmp_path)  # type: ignore[arg-type]
    agent.spawn((1.0, 2.0, 0.0))
    runner = threading.Thread(target=agent.run, daemon=True)
    runner.start()
    assert bus.sending_heartbeat.wait(5.0)
    agent.stop.set()
    runner.join(5.0)
    bus.closed = True
    time.sleep(0.5)
    assert "heartbeat" not in bus.handler_errors
