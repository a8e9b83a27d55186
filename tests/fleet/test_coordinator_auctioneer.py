"""The auctioneer without a bus: its publish function is a stand-in that answers each call by
handing each robot's bids, one message a robot, to the auctioneer's bid handler, as the bus's
thread would."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np
import pytest

from fleet.coordinator.auctioneer import Auctioneer, Sale
from fleet.params import CoordinatorParams
from fleet.protocol import AuctionCall, Bids, Keys, Message
from planners import auction

KEYS = Keys("test")
Prices = dict[tuple[str, str], tuple[float, float]]  # (lot, robot) -> (marginal_s, total_s)


class Bidders:
    """The bidders: each robot answers a call with its prices for the lots it has one for, in
    one message (robots with none stay silent); then ``also`` sees the call."""

    def __init__(
        self,
        prices: Prices,
        timeout_s: float = 5.0,
        also: Callable[[AuctionCall], None] = lambda _call: None,
    ) -> None:
        self.prices = prices
        self.also = also
        self.calls: list[tuple[str, AuctionCall, bool]] = []
        self.sales: list[Sale] = []
        params = CoordinatorParams(bid_timeout_s=timeout_s)
        self.auctioneer = Auctioneer(KEYS, self.publish, params, self.sales.append)

    def publish(self, key: str, msg: Message, control: bool) -> None:
        assert isinstance(msg, AuctionCall)
        self.calls.append((key, msg, control))
        for robot in sorted({r for _, r in self.prices}):
            mine = {lot: p for (lot, r), p in self.prices.items() if r == robot}
            lots = [lot for lot in msg.lots if lot in mine]
            if lots:
                self.auctioneer.on_bid(
                    KEYS.bids(robot),
                    _bids(robot, lots, msg.round, *zip(*(mine[lot] for lot in lots), strict=True)),
                )
        self.also(msg)

    def sell(
        self, lots: list[str], bidders: set[str], market: set[str] | None = None
    ) -> Sale | None:
        rnd = self.auctioneer.call(0.0, {lot: _lot(lot) for lot in lots}, frozenset(bidders))
        return self.auctioneer.award(rnd, bidders if market is None else market)


def _lot(lot: str) -> auction.Lot:
    return auction.Lot(lot, (lot,), np.zeros(2), np.ones(2), 1.0, 1.0)


def _bids(
    robot: str,
    lots: list[str],
    round_: int = 1,
    marginal: tuple[float, ...] | None = None,
    total: tuple[float, ...] | None = None,
    declined: tuple[int, ...] | None = None,
) -> Bids:
    k = len(lots)
    return Bids(
        0.0,
        round_,
        robot,
        lots,
        np.array(marginal if marginal is not None else [1.0] * k, dtype=float),
        np.array(total if total is not None else [1.0] * k, dtype=float),
        np.zeros(k, dtype=np.uint8),
        np.array(declined if declined is not None else [0] * k, dtype=np.uint8),
    )


PRICES: Prices = {
    ("t01", "robot-0"): (5.0, 50.0),
    ("t01", "robot-1"): (20.0, 30.0),  # the lowest total: MiniMax's winner
    ("t01", "robot-2"): (25.0, 35.0),
    ("t02", "robot-0"): (10.0, 60.0),
    ("t02", "robot-1"): (8.0, 31.0),
    ("t02", "robot-2"): (3.0, 40.0),  # the lowest marginal, not the winner
}
ROBOTS = {"robot-0", "robot-1", "robot-2"}


def test_the_best_bid_by_minimax_wins_and_is_reported() -> None:
    lot, robot = "t01", "robot-1"
    m = Bidders(PRICES)
    sale = m.sell(["t01", "t02"], ROBOTS)
    assert sale is not None and m.sales == [sale]
    assert (sale.best.task, sale.best.robot) == (lot, robot)
    assert (sale.best.marginal_s, sale.best.total_s) == PRICES[(lot, robot)]
    assert sale.lot.id == lot and sale.round == 1
    # the auction log: every robot's bid on the lot sold
    assert sorted((b.task, b.robot) for b in sale.bids) == sorted(k for k in PRICES if k[0] == lot)
    # both lots were called in one message, as control traffic, in round 1
    assert [(key, c.lots, c.round, control) for key, c, control in m.calls] == [
        (KEYS.call(), ["t01", "t02"], 1, True)
    ]


@pytest.mark.parametrize(
    ("prices", "winner"),
    [
        # equal totals: the lower marginal wins
        ({("t01", "robot-0"): (9.0, 30.0), ("t01", "robot-1"): (7.0, 30.0)}, "robot-1"),
        # equal totals and marginals: the lower robot id
        ({("t01", "robot-1"): (7.0, 30.0), ("t01", "robot-0"): (7.0, 30.0)}, "robot-0"),
    ],
)
def test_ties_are_broken_by_marginal_then_robot_id(prices: Prices, winner: str) -> None:
    sale = Bidders(prices).sell(["t01"], {"robot-0", "robot-1"})
    assert sale is not None and sale.best.robot == winner


def test_equal_bids_of_one_robot_go_to_the_lower_task_id() -> None:
    prices = {("t02", "robot-0"): (7.0, 30.0), ("t01", "robot-0"): (7.0, 30.0)}
    sale = Bidders(prices).sell(["t02", "t01"], {"robot-0"})
    assert sale is not None and sale.best.task == "t01"


def test_a_robot_that_left_the_market_during_the_round_does_not_win() -> None:
    m = Bidders(PRICES)
    sale = m.sell(["t01", "t02"], ROBOTS, market={"robot-0", "robot-2"})
    assert sale is not None and (sale.best.task, sale.best.robot) == ("t01", "robot-2")
    assert {b.robot for b in sale.bids} == {"robot-0", "robot-2"}
    assert m.sell(["t01", "t02"], ROBOTS, market=set()) is None
    assert m.sales == [sale]


def test_each_kind_of_bad_bid_is_counted_and_ignored() -> None:
    def bad(msg: AuctionCall) -> None:
        """Bad answers arriving while the round is open, after robot-0's good one."""
        nan, r = math.nan, msg.round
        answers: list[tuple[str, Bids]] = [
            (KEYS.bids("robot-1"), _bids("robot-0", ["t01"])),  # sent under another's key
            (KEYS.bids("robot-1"), _bids("robot-1", ["t01"], marginal=(nan,))),
            (KEYS.bids("robot-1"), _bids("robot-1", ["t01"], total=(-1.0,))),
            (KEYS.bids("robot-1"), _bids("robot-1", ["t01"], marginal=(1.0, 2.0))),  # 2 for 1
            (KEYS.bids("robot-1"), _bids("robot-1", ["t01", "t01"])),  # a lot twice
            (KEYS.bids("robot-1"), _bids("robot-1", ["t01"], round_=r - 1)),
            (KEYS.bids("robot-1"), _bids("robot-1", ["t09"])),  # a lot not called
            (KEYS.bids("robot-9"), _bids("robot-9", ["t01"], marginal=(0.0,), total=(0.0,))),
            (KEYS.bids("robot-0"), _bids("robot-0", ["t01"], marginal=(0.0,), total=(0.0,))),
        ]
        for key, bids in answers:
            m.auctioneer.on_bid(key, bids)

    good = (4.0, 40.0)
    m = Bidders({("t01", "robot-0"): good}, timeout_s=0.2, also=bad)
    a = m.auctioneer
    a.on_bid(KEYS.bids("robot-1"), _bids("robot-1", ["t01"]))  # no round open
    sale = m.sell(["t01"], {"robot-0", "robot-1"})
    a.on_bid(KEYS.bids("robot-1"), _bids("robot-1", ["t01"]))  # the round has closed
    assert a.rejected() == {"malformed": 5, "late": 4, "not in the market": 1, "duplicate": 1}
    # the first answer of robot-0 stands, and robot-1's silence did not stop the round's sale
    assert sale is not None and sale.best.robot == "robot-0"
    assert (sale.best.marginal_s, sale.best.total_s) == good
    assert len(sale.bids) == 1


def test_a_declined_bid_never_wins_and_an_empty_answer_closes_the_round() -> None:
    def answer(msg: AuctionCall) -> None:
        a.on_bid(KEYS.bids("robot-0"), _bids("robot-0", ["t01"], 1, (1.0,), (1.0,), (1,)))
        a.on_bid(KEYS.bids("robot-1"), _bids("robot-1", ["t01"], 1, (9.0,), (90.0,)))
        a.on_bid(KEYS.bids("robot-2"), _bids("robot-2", []))  # holds it, say: nothing to offer

    m = Bidders({}, timeout_s=60.0, also=answer)
    a = m.auctioneer
    t0 = time.monotonic()
    sale = m.sell(["t01"], {"robot-0", "robot-1", "robot-2"})
    # every bidder answered: the round closed far short of its minute (loose on purpose)
    assert time.monotonic() - t0 < 30.0
    assert sale is not None and sale.best.robot == "robot-1"
    assert [b.robot for b in sale.bids] == ["robot-1"]


def test_a_bid_may_take_off_what_its_lot_is_worth_and_no_more() -> None:
    # a frontier worth 10 s: a robot next to it bids -9 s; -11 s is more than it is worth
    worth = auction.Lot("f01", ("f01",), np.zeros(2), np.ones(2), 0.0, 5.0, 10.0)
    prices = {("f01", "robot-0"): (-9.0, -9.0), ("f01", "robot-1"): (-11.0, -11.0)}
    m = Bidders(prices, timeout_s=0.2)
    rnd = m.auctioneer.call(0.0, {"f01": worth}, frozenset({"robot-0", "robot-1"}))
    sale = m.auctioneer.award(rnd, {"robot-0", "robot-1"})
    assert sale is not None and sale.best.robot == "robot-0"
    assert m.auctioneer.rejected() == {"malformed": 1}
    assert list(m.calls[0][1].gains_s) == [10.0]
    # a bid of another round is late, whatever it takes off
    m.auctioneer.on_bid(KEYS.bids("robot-0"), _bids("robot-0", ["f01"], 0, (-50.0,), (-50.0,)))
    assert m.auctioneer.rejected() == {"malformed": 1, "late": 1}


def test_a_round_waits_for_a_silent_bidder_only_until_the_bid_timeout() -> None:
    # every bidder bid: the round closes at once, far short of a minute's timeout (the bound
    # is loose on purpose: a busy machine must not fail it)
    m = Bidders({("t01", "robot-0"): (4.0, 40.0)}, timeout_s=60.0)
    t0 = time.monotonic()
    assert m.sell(["t01"], {"robot-0"}) is not None
    assert time.monotonic() - t0 < 30.0
    m = Bidders({("t01", "robot-0"): (4.0, 40.0)}, timeout_s=0.3)
    t0 = time.monotonic()
    sale = m.sell(["t01"], {"robot-0", "robot-1"})
    assert time.monotonic() - t0 >= 0.3
    assert sale is not None and sale.round == 1


def test_a_resumed_auctioneer_numbers_on_and_keeps_its_counts() -> None:
    params = CoordinatorParams(bid_timeout_s=0.05)
    a = Auctioneer(KEYS, lambda *_: None, params, lambda _: None, None, 41, {"late": 3})
    a.on_bid(KEYS.bids("robot-0"), _bids("robot-0", ["t01"]))
    assert a.call(0.0, {"t01": _lot("t01")}, frozenset({"robot-0"})).number == 42
    assert a.rejected() == {"late": 4}
