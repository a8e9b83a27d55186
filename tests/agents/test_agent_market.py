"""The robot's side of the market without a bus: its queue, its prices, its swept pieces, and
the rounds it bids in."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from agents.agent import Agent
from agents.follow.state import FollowState
from agents.market import MarketClient, swept_pieces
from agents.pose_source import OdometryPose
from fleet.params import load_fleet_config
from fleet.protocol import Award, BatteryState, Bid, Docks, Keys, Message, TaskCall
from planners.battery import BatterySpec
from planners.grid import GridMap

SPEED = 0.25


def _client() -> MarketClient:
    return MarketClient("robot-0", SPEED, 0.17, 0.65, 0.35)


def _award(seq: int, tasks: list[tuple[str, tuple, tuple, float]]) -> Award:
    return Award(
        0.0,
        seq,
        "robot-0",
        [t for t, *_ in tasks],
        np.array([e for _, e, _, _ in tasks], dtype=float).reshape(-1, 2),
        np.array([x for _, _, x, _ in tasks], dtype=float).reshape(-1, 2),
        np.array([s for *_, s in tasks], dtype=float),
    )


def _call(task: str, entry: tuple, exit_: tuple, time_s: float) -> TaskCall:
    return TaskCall(0.0, 3, task, *entry, *exit_, time_s, 1.0)


def test_only_a_newer_award_of_this_robot_changes_its_queue() -> None:
    m = _client()
    assert m.on_award(_award(2, [("t01", (0, 0), (1, 0), 10.0)]))
    assert m.holds("t01") and m.seq == 2
    assert not m.on_award(_award(1, []))
    assert not m.on_award(_award(2, []))
    other = Award(0.0, 9, "robot-1", [], np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0))
    assert not m.on_award(other)
    assert m.on_award(_award(3, []))
    assert not m.holds("t01") and m.queue == ()


def test_bids_price_from_the_end_of_the_queue_and_skip_what_it_holds() -> None:
    m = _client()
    m.on_award(_award(1, [("t01", (0, 0), (2, 0), 10.0)]))
    c = m.commitment((0.0, 0.0, 0.0), None, [], 0.0)
    # nothing driven yet: travel to t01 (0 s) and t01 itself
    assert c.total_s == pytest.approx(10.0)
    calls = [_call("t01", (0, 0), (2, 0), 10.0), _call("t02", (5, 0), (3, 0), 8.0)]
    (bid,) = m.bids(calls, c)
    assert bid.task == "t02" and bid.robot == "robot-0" and bid.round == 3
    # the nearer end of t02 from t01's end (2, 0) is its exit (3, 0), 1 m away
    assert bid.reverse
    assert bid.marginal_s == pytest.approx(1.0 / SPEED + 8.0)
    assert bid.total_s == pytest.approx(10.0 + bid.marginal_s)


def test_the_plan_being_driven_counts_by_the_length_left() -> None:
    m = _client()
    m.on_award(_award(1, [("t01", (0, 0), (4, 0), 20.0), ("t02", (4, 0), (8, 0), 20.0)]))
    waypoints = np.array([[0.0, 0.0], [4.0, 0.0], [8.0, 0.0]])
    follow = FollowState(waypoints, index=2)
    c = m.commitment((6.0, 0.0, 0.0), follow, ["t01", "t02"], 40.0)
    # 2 m of 8 left of a 40 s plan; nothing queued after it
    assert c.total_s == pytest.approx(10.0)
    assert c.end == (8.0, 0.0)


def test_travel_is_priced_around_the_walls_of_the_floor_plan() -> None:
    occupied = np.zeros((40, 40), dtype=bool)
    occupied[:30, 20] = True  # a wall from the bottom up to y = 3 m, at x = 2 m
    floor = GridMap(occupied, np.zeros_like(occupied), 0.1, (0.0, 0.0))
    m = _client()
    straight = m.commitment((1.0, 1.0, 0.0), None, [], 0.0)
    call = [_call("t09", (3.0, 1.0), (3.0, 1.2), 5.0)]
    (blind,) = m.bids(call, straight)
    m.use_floor(floor)
    (aware,) = m.bids(call, straight)
    assert blind.marginal_s == pytest.approx(2.0 / SPEED + 5.0)
    # over the wall's end at y = 3 m and back down: about 2 x 2.2 m
    assert aware.marginal_s > 4.0 / SPEED + 5.0


def test_a_piece_is_swept_once_the_robot_reached_its_far_end() -> None:
    waypoints = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0], [4.0, 0.0]])
    # waypoint 1 is where the sweep starts: three pieces, 1-2, 2-3, 3-4
    assert swept_pieces(FollowState(waypoints, index=2), 1).tolist() == [0, 0, 0]
    assert swept_pieces(FollowState(waypoints, index=3), 1).tolist() == [1, 0, 0]
    assert swept_pieces(FollowState(waypoints, index=5), 1).tolist() == [1, 1, 1]
    assert swept_pieces(None, 0).tolist() == []


def _battery_client() -> MarketClient:
    spec = BatterySpec(enabled=True, capacity_s=100.0, recharge_threshold=0.1, recharge_to=0.9)
    m = MarketClient("robot-0", SPEED, 0.17, 0.65, 0.35, spec)
    m.docks = np.array([[0.0, 0.0]])
    return m


def test_a_task_it_cannot_finish_and_get_home_from_is_declined() -> None:
    """At 0.25 m/s: 4 s to the task, 10 s of it, 4 s home from its far end (1 m from the dock
    at (0, 0)) is 18 s, 0.18 of a 100 s charge."""
    m = _battery_client()
    commitment = m.commitment((0.0, 0.0, 0.0), None, [], 0.0)
    call = _call("t01", (1.0, 0.0), (0.0, 1.0), 10.0)
    (ok,) = m.bids([call], commitment, BatteryState(0.0, 0.5, False))
    assert not ok.declined and ok.total_s == pytest.approx(14.0)
    (short,) = m.bids([call], commitment, BatteryState(0.0, 0.179, False))
    (enough,) = m.bids([call], commitment, BatteryState(0.0, 0.181, False))
    assert short.declined and not enough.declined
    # what it has won counts too: 20 s more work before it
    m.on_award(_award(1, [("t00", (0.0, 0.0), (0.0, 0.0), 20.0)]))
    (after,) = m.bids(
        [call], m.commitment((0.0, 0.0, 0.0), None, [], 0.0), BatteryState(0.0, 0.3, False)
    )
    assert after.declined


def test_a_robot_below_the_threshold_or_charging_does_not_bid() -> None:
    m = _battery_client()
    commitment = m.commitment((0.0, 0.0, 0.0), None, [], 0.0)
    call = _call("t01", (1.0, 0.0), (0.0, 1.0), 10.0)
    assert m.bids([call], commitment, BatteryState(0.0, 0.09, False)) == []
    assert m.bids([call], commitment, BatteryState(0.0, 0.5, True)) == []
    assert len(m.bids([call], commitment, BatteryState(0.0, 0.95, True))) == 1


def test_without_batteries_nothing_is_declined() -> None:
    (bid,) = _client().bids(
        [_call("t01", (1.0, 0.0), (0.0, 1.0), 1e6)],
        _client().commitment((0.0, 0.0, 0.0), None, [], 0.0),
        BatteryState(0.0, 0.0, False),
    )
    assert not bid.declined


class _NoFloorBus:
    """What the agent's bidding needs of a bus: its bids are kept; no coordinator serves a
    floor plan (an exploring fleet's)."""

    def __init__(self) -> None:
        self.keys = Keys()
        self.bids: list[Bid] = []

    def publish(self, key: str, msg: Message, control: bool = False) -> None:
        if isinstance(msg, Bid):
            self.bids.append(msg)

    def request(self, *_args: object, **_kwargs: object) -> Message:
        raise TimeoutError("no floor plan served")

    def drop_implausible(self, key: str, sender: str, why: str, n: int = 1) -> None:
        return None


def test_an_agent_bids_only_on_rounds_that_count_it_in_the_market() -> None:
    """A robot just placed (or found in its saved map) hears rounds called before the
    coordinator knew it was ready; bids on them would be refused as from a robot not in the
    market."""
    bus = _NoFloorBus()
    agent = Agent(bus, "robot-0", load_fleet_config())  # type: ignore[arg-type]
    agent.pose_source = OdometryPose((0.0, 0.0, 0.0))
    before = dataclasses.replace(_call("t01", (1.0, 0.0), (2.0, 0.0), 5.0), bidders=["robot-1"])
    agent._bid([before])
    assert bus.bids == []
    counted = dataclasses.replace(before, round=4, bidders=["robot-0", "robot-1"])
    agent._bid([counted])
    assert [(b.task, b.robot) for b in bus.bids] == [("t01", "robot-0")]


def test_the_battery_the_agent_hears_is_what_it_bids_on() -> None:
    """The wiring, not the pricing: a reading heard on the robot's battery key reaches the
    agent's bids (a robot below its threshold bids nothing, one charged bids), whatever the
    market client would do with a reading handed to it by hand."""
    cfg = load_fleet_config()
    battery = dataclasses.replace(cfg.robot.battery, enabled=True)
    cfg = dataclasses.replace(cfg, robot=dataclasses.replace(cfg.robot, battery=battery))
    bus = _NoFloorBus()
    agent = Agent(bus, "robot-0", cfg)  # type: ignore[arg-type]
    agent.pose_source = OdometryPose((0.0, 0.0, 0.0))
    key = bus.keys.robot("robot-0", "battery")
    call = _call("t01", (1.0, 0.0), (2.0, 0.0), 5.0)
    agent._on_battery(key, BatteryState(0.0, battery.recharge_threshold / 2, False))
    agent._bid([call])
    assert bus.bids == []
    agent._on_battery(key, BatteryState(0.0, 1.0, False))
    agent._bid([dataclasses.replace(call, round=call.round + 1)])
    assert [(b.task, b.declined) for b in bus.bids] == [("t01", False)]


class _DocksOnlyBus(_NoFloorBus):
    """An exploring coordinator's with batteries: no floor plan, but the docks."""

    def __init__(self, docks: np.ndarray) -> None:
        super().__init__()
        self.docks = docks

    def request(self, key: str, *_args: object, **_kwargs: object) -> Message:
        if key == self.keys.docks():
            return Docks(0.0, self.docks)
        raise TimeoutError("no floor plan served")


@pytest.mark.parametrize(("dock_x", "declined"), [(-20.0, True), (3.0, False)])
def test_with_no_floor_plan_the_agent_still_prices_the_way_home_to_the_docks_served(
    dock_x: float, declined: bool
) -> None:
    """Exploring with batteries, the coordinator serves docks and no floor plan: the agent
    prices each call with the trip home from its end (a call it could finish but not get home
    from is declined), pricing travel on its own map."""
    cfg = load_fleet_config()
    battery = dataclasses.replace(cfg.robot.battery, enabled=True, capacity_s=100.0)
    cfg = dataclasses.replace(cfg, robot=dataclasses.replace(cfg.robot, battery=battery))
    bus = _DocksOnlyBus(np.array([[dock_x, 0.0, 0.0]]))
    agent = Agent(bus, "robot-0", cfg)  # type: ignore[arg-type]
    agent.pose_source = OdometryPose((0.0, 0.0, 0.0))
    agent._on_battery(bus.keys.robot("robot-0", "battery"), BatteryState(0.0, 0.5, False))
    agent._bid([_call("t01", (1.0, 0.0), (2.0, 0.0), 5.0)])
    assert agent.market.docks.tolist() == [[dock_x, 0.0]]
    # 5 s of work on half a charge, and 22 m home at the transit speed (declined) or 1 m
    assert [(b.task, b.declined) for b in bus.bids] == [("t01", declined)]
