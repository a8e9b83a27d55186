"""The auctioneer: one round of the market at a time — calls, bids, the winner, the sale.

Sequential single-item auctions (Koenig et al. 2006): a round calls every lot on sale in one
:class:`AuctionCall` on ``coord/call``; every robot in the market answers with one
:class:`Bids` on ``coord/bids/<robot>``, its price for each lot from its own pose and
commitments; the best bid by MiniMax (``planners.auction.ranked``: the lowest committed time
with the lot) wins, and the sale goes to the result callback, as Open-RMF's bidding
``Auctioneer`` reports each winner. One message each way per robot and round, not one per lot:
a round of 500 lots and 20 robots is 21 messages, not 10 500. A robot's bids that are malformed,
late (another round, or a lot not called), from a robot that is not in the market, or a second
answer to the round are counted by reason (one a message) and ignored.

The auctioneer knows no job: what is on sale, who may bid and what a sale changes are its
caller's. It collects a round's bids on the bus's thread (:meth:`Auctioneer.on_bid`) while the
caller waits in :meth:`Auctioneer.call`, for ``bid_timeout_s`` at most, and sooner once every
bidder has answered.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, field

import numpy as np

from fleet.coordinator.journal import Publish
from fleet.params import CoordinatorParams
from fleet.protocol import AuctionCall, Bids, Keys
from planners import auction

log = logging.getLogger("coordinator")


@dataclass
class Round:
    """One call of the lots on sale to the bidders, and the answers it drew, by robot."""

    number: int
    lots: Mapping[str, auction.Lot]
    bidders: frozenset[str]
    bids: dict[str, Bids] = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class Sale:
    """A round's result: the lot sold, the winning bid, and the bids on that lot from the robots
    in the market when the round closed (the auction log)."""

    round: int
    lot: auction.Lot
    best: auction.Bid
    bids: list[auction.Bid]


class Auctioneer:
    """Calls rounds, validates and collects their bids, and reports each sale to ``on_sale``."""

    def __init__(
        self,
        keys: Keys,
        publish: Publish,
        params: CoordinatorParams,
        on_sale: Callable[[Sale], None],
        stop: threading.Event | None = None,
        round_seq: int = 0,
        rejected: Mapping[str, int] | None = None,
    ) -> None:
        """``round_seq`` and ``rejected`` carry on a resumed job's round numbers and counts;
        ``stop`` set ends a round's wait."""
        self.keys = keys
        self.publish = publish
        self.params = params
        self.on_sale = on_sale
        self.stop = stop if stop is not None else threading.Event()
        self.round_seq = round_seq
        self._rejected: Counter[str] = Counter(rejected or {})
        self._open: Round | None = None
        self._cond = threading.Condition()

    def rejected(self) -> dict[str, int]:
        """The bids ignored so far, by reason."""
        with self._cond:
            return dict(self._rejected)

    def on_bid(self, key: str, msg: Bids) -> None:
        """A robot's answer heard on ``key``: kept for the open round, or counted and ignored."""
        rid = self.keys.robot_of(key)
        with self._cond:
            rnd = self._open
            why = _refused(msg, rid, key == self.keys.bids(msg.robot), rnd)
            if why is None:
                assert rnd is not None  # with no round open an answer is late
                rnd.bids[rid] = msg
                self._cond.notify_all()
                return
            self._rejected[why] += 1
            n = self._rejected[why]
        if n == 1 or n % 100 == 0:
            log.warning("ignored %s bids from %s in round %d (%d so far)", why, rid, msg.round, n)

    def call(self, clock: float, lots: Mapping[str, auction.Lot], bidders: frozenset[str]) -> Round:
        """Call every lot; the round with the answers that came within ``bid_timeout_s`` (all,
        usually sooner)."""
        self.round_seq += 1
        rnd = Round(self.round_seq, dict(lots), bidders)
        with self._cond:
            self._open = rnd
        on_sale = list(rnd.lots.values())
        call = AuctionCall(
            clock,
            rnd.number,
            [lot.id for lot in on_sale],
            np.array([lot.entry for lot in on_sale], dtype=float).reshape(-1, 2),
            np.array([lot.exit for lot in on_sale], dtype=float).reshape(-1, 2),
            np.array([lot.time_s for lot in on_sale], dtype=float),
            np.array([lot.area_m2 for lot in on_sale], dtype=float),
            np.array([lot.gain_s for lot in on_sale], dtype=float),
            sorted(bidders),
        )
        self.publish(self.keys.call(), call, True)
        deadline = time.monotonic() + self.params.bid_timeout_s
        with self._cond:
            while len(rnd.bids) < len(bidders) and not self.stop.is_set():
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                self._cond.wait(left)
            self._open = None
        return rnd

    def award(
        self,
        rnd: Round,
        market: Collection[str],
        allowed: Callable[[auction.Lot, str], bool] | None = None,
    ) -> Sale | None:
        """The round's best bid (``planners.auction.ranked``) among those of robots still in
        ``market``, not declined (and, with ``allowed``, that may win the lot it is for) wins:
        the sale, also reported to ``on_sale``; None (and a warning) if no such robot bid."""
        live = [b for rid, b in rnd.bids.items() if rid in market]
        lots = np.array([lot for b in live for lot in b.lots], dtype=str)
        robots = np.repeat(
            np.array([b.robot for b in live], dtype=str), [len(b.lots) for b in live]
        )
        marginal, total, reverse, declined = (
            np.concatenate([getattr(b, f) for b in live] or [np.zeros(0)])
            for f in ("marginal_s", "total_s", "reverse", "declined")
        )
        offered = np.flatnonzero(declined == 0)
        order = offered[
            auction.ranked(total[offered], marginal[offered], robots[offered], lots[offered])
        ]
        won = next(
            (i for i in order if allowed is None or allowed(rnd.lots[lots[i]], str(robots[i]))),
            None,
        )
        if won is None:
            self._none_may_win(rnd, len(lots))
            return None
        sold = lots[won]
        bids = [
            auction.Bid(
                str(sold), str(robots[i]), float(marginal[i]), float(total[i]), bool(reverse[i])
            )
            for i in offered[lots[offered] == sold]
        ]
        best = next(b for b in bids if b.robot == robots[won])
        sale = Sale(rnd.number, rnd.lots[str(sold)], best, bids)
        self.on_sale(sale)
        return sale

    def _none_may_win(self, rnd: Round, prices: int) -> None:
        if rnd.bids:
            log.info(
                "auction round %d: %d bid(s) from %d robot(s), none may win (its robot left the "
                "market, its lot changed meanwhile, its robot tried it, or declined it on its "
                "charge)",
                rnd.number,
                prices,
                len(rnd.bids),
            )
        else:
            log.warning(
                "auction round %d: no answer from %s within %.1f s",
                rnd.number,
                ", ".join(sorted(rnd.bidders)),
                self.params.bid_timeout_s,
            )


def _refused(msg: Bids, rid: str, own_key: bool, rnd: Round | None) -> str | None:
    """Why a robot's answer is ignored (None: it is not): malformed (sent under another's key,
    arrays of the wrong length, a lot twice, a number not finite or below what its lot is worth
    beyond its work), late (no round open, another round, a lot not called), from a robot not
    in the market, or a second answer of the robot to the round."""
    numbers = np.concatenate([msg.marginal_s, msg.total_s]) if msg.consistent() else None
    if (
        msg.robot != rid
        or not own_key
        or numbers is None
        or not np.isfinite(numbers).all()
        or len(set(msg.lots)) != len(msg.lots)
    ):
        return "malformed"
    if rnd is None or msg.round != rnd.number or any(lot not in rnd.lots for lot in msg.lots):
        return "late"
    # a bid takes off at most what its lot is worth beyond its work
    least = -np.array([rnd.lots[lot].gain_s for lot in msg.lots], dtype=float)
    if (msg.marginal_s < least).any() or (msg.total_s < least).any():
        return "malformed"
    if rid not in rnd.bidders:
        return "not in the market"
    if rid in rnd.bids:
        return "duplicate"
    return None
