"""The robot's side of the market without a bus: its queue, its prices, its swept pieces, the
rounds it bids in, and the loop that answers each call with one message."""

from __future__ import annotations

import dataclasses
import threading
import time

import numpy as np
import pytest

from agents.agent import Agent
from agents.bidding import Bidder
from agents.follow.state import FollowState
from agents.market import MarketClient, swept_pieces
from agents.pose_source import OdometryPose
from fleet.params import load_fleet_config
from fleet.protocol import AuctionCall, Award, BatteryState, Bids, Docks, Keys, Message
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


def _call(*lots: tuple[str, tuple, tuple, float], round_: int = 3) -> AuctionCall:
    """Round ``round_`` calling ``lots``, each (id, entry, exit, time_s)."""
    k = len(lots)
    return AuctionCall(
        0.0,
        round_,
        [lot for lot, *_ in lots],
        np.array([e for _, e, _, _ in lots], dtype=float).reshape(-1, 2),
        np.array([x for _, _, x, _ in lots], dtype=float).reshape(-1, 2),
        np.array([t for *_, t in lots], dtype=float),
        np.ones(k),
        np.zeros(k),
    )


def _only(bids: Bids | None) -> tuple[str, float, float, bool, bool]:
    """The one bid of an answer: (lot, marginal_s, total_s, reverse, declined)."""
    assert bids is not None and len(bids.lots) == 1, bids
    return (
        bids.lots[0],
        float(bids.marginal_s[0]),
        float(bids.total_s[0]),
        bool(bids.reverse[0]),
        bool(bids.declined[0]),
    )


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
    answer = m.bids(_call(("t01", (0, 0), (2, 0), 10.0), ("t02", (5, 0), (3, 0), 8.0)), c)
    assert answer.robot == "robot-0" and answer.round == 3
    lot, marginal, total, reverse, _ = _only(answer)
    assert lot == "t02"
    # the nearer end of t02 from t01's end (2, 0) is its exit (3, 0), 1 m away
    assert reverse
    assert marginal == pytest.approx(1.0 / SPEED + 8.0)
    assert total == pytest.approx(10.0 + marginal)


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
    call = _call(("t09", (3.0, 1.0), (3.0, 1.2), 5.0))
    blind = _only(m.bids(call, straight))[1]
    m.use_floor(floor)
    aware = _only(m.bids(call, straight))[1]
    assert blind == pytest.approx(2.0 / SPEED + 5.0)
    # over the wall's end at y = 3 m and back down: about 2 x 2.2 m
    assert aware > 4.0 / SPEED + 5.0


def test_a_lot_called_again_unchanged_is_priced_from_memory_as_it_would_be_afresh() -> None:
    """Between two rounds only the last winner's end moves: a robot prices again only the lots
    that are new or changed (a region's id is sold again with other ends), and only when its
    end moved, all of them; every answer equals one priced afresh."""
    occupied = np.zeros((40, 40), dtype=bool)
    occupied[:30, 20] = True  # a wall, so that travel is not the straight line
    floor = GridMap(occupied, np.zeros_like(occupied), 0.1, (0.0, 0.0))

    def fresh(call: AuctionCall, at: tuple[float, float, float]) -> Bids:
        m = _client()
        m.use_floor(floor)
        return m.bids(call, m.commitment(at, None, [], 0.0))

    m = _client()
    m.use_floor(floor)
    a, b = ("a", (3.0, 1.0), (3.0, 2.0), 5.0), ("b", (1.0, 3.5), (0.5, 3.5), 4.0)
    region, moved_region = ("r0", (3.5, 0.5), (1.5, 0.5), 9.0), ("r0", (3.5, 0.5), (3.5, 3.8), 9.0)
    calls = [
        ((1.0, 1.0, 0.0), _call(a, b, region, round_=1), 3),
        ((1.0, 1.0, 0.0), _call(b, moved_region, round_=2), 1),  # only the region's ends moved
        ((1.0, 1.0, 0.0), _call(b, moved_region, round_=3), 0),
        ((1.5, 1.0, 0.0), _call(b, moved_region, round_=4), 2),  # it moved: all afresh
    ]
    for at, call, priced in calls:
        before = m.priced
        answer = m.bids(call, m.commitment(at, None, [], 0.0))
        assert m.priced - before == priced, call.round
        want = fresh(call, at)
        assert answer.lots == want.lots
        assert answer.marginal_s.tolist() == want.marginal_s.tolist()
        assert answer.total_s.tolist() == want.total_s.tolist()
        assert answer.reverse.tolist() == want.reverse.tolist()


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
    call = _call(("t01", (1.0, 0.0), (0.0, 1.0), 10.0))
    _, _, total, _, declined = _only(m.bids(call, commitment, BatteryState(0.0, 0.5, False)))
    assert not declined and total == pytest.approx(14.0)
    assert _only(m.bids(call, commitment, BatteryState(0.0, 0.179, False)))[4]
    assert not _only(m.bids(call, commitment, BatteryState(0.0, 0.181, False)))[4]
    # what it has won counts too: 20 s more work before it
    m.on_award(_award(1, [("t00", (0.0, 0.0), (0.0, 0.0), 20.0)]))
    after = m.bids(
        call, m.commitment((0.0, 0.0, 0.0), None, [], 0.0), BatteryState(0.0, 0.3, False)
    )
    assert _only(after)[4]


def test_the_way_home_is_priced_to_the_nearest_dock_for_every_lot_at_once() -> None:
    """Two docks, three lots: each lot's far end is priced home to the dock nearer to it (the
    lots whose far end is 30 m from both docks are declined on a 100 s charge)."""
    m = _battery_client()
    m.docks = np.array([[0.0, 0.0], [10.0, 0.0]])
    commitment = m.commitment((5.0, 0.0, 0.0), None, [], 0.0)
    lots = [("a", (4.0, 0.0), (1.0, 0.0), 1.0), ("b", (6.0, 0.0), (9.0, 0.0), 1.0)]
    call = _call(*lots, ("c", (5.0, 1.0), (5.0, 30.0), 1.0))
    assert m.home_times(np.array([[1.0, 0.0], [9.0, 0.0]])) == pytest.approx([4.0, 4.0])
    answer = m.bids(call, commitment, BatteryState(0.0, 1.0, False))
    assert answer.lots == ["a", "b", "c"] and answer.declined.tolist() == [0, 0, 1]


def test_a_robot_below_the_threshold_or_charging_does_not_bid() -> None:
    m = _battery_client()
    commitment = m.commitment((0.0, 0.0, 0.0), None, [], 0.0)
    call = _call(("t01", (1.0, 0.0), (0.0, 1.0), 10.0))
    assert m.bids(call, commitment, BatteryState(0.0, 0.09, False)).lots == []
    assert m.bids(call, commitment, BatteryState(0.0, 0.5, True)).lots == []
    assert len(m.bids(call, commitment, BatteryState(0.0, 0.95, True)).lots) == 1


def test_without_batteries_nothing_is_declined() -> None:
    answer = _client().bids(
        _call(("t01", (1.0, 0.0), (0.0, 1.0), 1e6)),
        _client().commitment((0.0, 0.0, 0.0), None, [], 0.0),
        BatteryState(0.0, 0.0, False),
    )
    assert not _only(answer)[4]


class _NoFloorBus:
    """What the agent's bidding needs of a bus: its bids are kept; no coordinator serves a
    floor plan (an exploring fleet's)."""

    def __init__(self) -> None:
        self.keys = Keys()
        self.bids: list[tuple[str, Bids]] = []

    def publish(self, key: str, msg: Message, control: bool = False) -> None:
        if isinstance(msg, Bids):
            self.bids.append((key, msg))

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
    before = dataclasses.replace(_call(("t01", (1.0, 0.0), (2.0, 0.0), 5.0)), bidders=["robot-1"])
    assert agent._answer(before) is None
    counted = dataclasses.replace(before, round=4, bidders=["robot-0", "robot-1"])
    answer = agent._answer(counted)
    assert answer is not None and (answer.lots, answer.robot) == (["t01"], "robot-0")


def test_an_agent_drops_a_call_whose_lot_arrays_disagree() -> None:
    """A call of two lots with the ends of one is no call to price (it raised in the pricing);
    it is counted as implausible and unanswered."""
    bus = _NoFloorBus()
    dropped: list[str] = []
    bus.drop_implausible = lambda key, sender, why, n=1: dropped.append(why)  # type: ignore[method-assign]
    agent = Agent(bus, "robot-0", load_fleet_config())  # type: ignore[arg-type]
    agent.pose_source = OdometryPose((0.0, 0.0, 0.0))
    call = _call(("t01", (1.0, 0.0), (2.0, 0.0), 5.0), ("t02", (3.0, 0.0), (4.0, 0.0), 5.0))
    short = dataclasses.replace(call, exits=call.exits[:1])
    assert agent._answer(short) is None and dropped == ["lot arrays of unequal length"]
    assert agent._answer(call) is not None


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
    call = _call(("t01", (1.0, 0.0), (2.0, 0.0), 5.0))
    agent._on_battery(key, BatteryState(0.0, battery.recharge_threshold / 2, False))
    low = agent._answer(call)
    assert low is not None and low.lots == []
    agent._on_battery(key, BatteryState(0.0, 1.0, False))
    assert _only(agent._answer(call))[0::4] == ("t01", False)


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
    answer = agent._answer(_call(("t01", (1.0, 0.0), (2.0, 0.0), 5.0)))
    assert agent.market.docks.tolist() == [[dock_x, 0.0]]
    # 5 s of work on half a charge, and 22 m home at the transit speed (declined) or 1 m
    assert _only(answer)[0::4] == ("t01", declined)


def test_the_bidder_answers_the_latest_call_once_on_its_own_key() -> None:
    """Two calls heard while the robot is busy: the older round has closed by the time it is
    free, so only the newer is answered, with one message on ``coord/bids/<robot>``; an
    answer that fails costs its round, never the loop."""
    bus = _NoFloorBus()
    failed: list[str] = []
    bus.handler_failed = failed.append  # type: ignore[attr-defined]
    m = _client()
    at = m.commitment((0.0, 0.0, 0.0), None, [], 0.0)

    def answer(call: AuctionCall) -> Bids:
        if call.round == 9:
            raise RuntimeError("a broken price")
        return m.bids(call, at)

    stop = threading.Event()
    bidder = Bidder(bus, "robot-0", answer, stop)  # type: ignore[arg-type]
    lot = ("t01", (1.0, 0.0), (2.0, 0.0), 5.0)
    bidder.on_call("", _call(lot, round_=4))
    bidder.on_call("", _call(lot, round_=5))
    bidder.on_call("", _call(lot, round_=3))  # a stray older call changes nothing
    thread = threading.Thread(target=bidder.loop)
    thread.start()
    try:
        deadline = time.monotonic() + 10.0
        while not bus.bids and time.monotonic() < deadline:
            time.sleep(0.01)
        bidder.on_call("", _call(lot, round_=9))
        while not failed and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        stop.set()
        thread.join(5.0)
    assert [(key, b.round, b.lots) for key, b in bus.bids] == [
        (bus.keys.bids("robot-0"), 5, ["t01"])
    ]
    assert failed == ["coord/call"] and bidder.answered == 1
