"""The auctioneer: one round of the market at a time — calls, bids, the winner, the sale.

Sequential single-item auctions (Koenig et al. 2006): a round calls every lot on sale on
``coord/task/<lot>``; every robot in the market answers each with a :class:`Bid` priced from its
own pose and commitments; the best bid by MiniMax (``planners.auction.winner``: the lowest
committed time with the lot) wins, and the sale goes to the result callback, as Open-RMF's
bidding ``Auctioneer`` reports each winner. Bids that are malformed, late (another round, or a
lot not called), from a robot that is not in the market, or duplicate are counted by reason and
ignored.

The auctioneer knows no job: what is on sale, who may bid and what a sale changes are its
caller's. It collects a round's bids on the bus's thread (:meth:`Auctioneer.on_bid`) while the
caller waits in :meth:`Auctioneer.call`, for ``bid_timeout_s`` at most, and sooner once every
bidder has bid on every lot.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import Counter
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, field

from fleet.coordinator.journal import Publish
from fleet.params import CoordinatorParams
from fleet.protocol import Bid, Keys, TaskCall
from planners import auction

log = logging.getLogger("coordinator")


@dataclass
class Round:
    """One call of the lots on sale to the bidders, and the bids it drew, by (lot, robot)."""

    number: int
    lots: Mapping[str, auction.Lot]
    bidders: frozenset[str]
    bids: dict[tuple[str, str], Bid] = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class Sale:
    """A round's result: the lot sold, the winning bid, and the round's bids from the robots in
    the market when it closed (the auction log)."""

    round: int
    lot: auction.Lot
    best: auction.Bid
    bids: list[Bid]


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

    def on_bid(self, key: str, msg: Bid) -> None:
        """A bid heard on ``key``: kept for the open round, or counted and ignored."""
        rid = self.keys.robot_of(key)
        with self._cond:
            rnd = self._open
            # a bid takes off at most what its lot is worth beyond its work (one for no lot of
            # the open round is late, whatever its numbers)
            lot = rnd.lots.get(msg.task) if rnd is not None and msg.round == rnd.number else None
            least = -lot.gain_s if lot is not None else -math.inf
            ok_numbers = all(math.isfinite(v) and v >= least for v in (msg.marginal_s, msg.total_s))
            if msg.robot != rid or not ok_numbers or key != self.keys.bid(msg.task, msg.robot):
                why = "malformed"
            elif rnd is None or msg.round != rnd.number or msg.task not in rnd.lots:
                why = "late"
            elif rid not in rnd.bidders:
                why = "not in the market"
            elif (msg.task, rid) in rnd.bids:
                why = "duplicate"
            else:
                rnd.bids[(msg.task, rid)] = msg
                self._cond.notify_all()
                return
            self._rejected[why] += 1
            n = self._rejected[why]
        if n == 1 or n % 100 == 0:
            log.warning("ignored a %s bid from %s on %s (%d so far)", why, rid, msg.task, n)

    def call(self, clock: float, lots: Mapping[str, auction.Lot], bidders: frozenset[str]) -> Round:
        """Call every lot; the round with the bids that came within ``bid_timeout_s`` (all,
        usually sooner)."""
        self.round_seq += 1
        rnd = Round(self.round_seq, dict(lots), bidders)
        with self._cond:
            self._open = rnd
        for lot in rnd.lots.values():
            call = TaskCall(
                clock,
                rnd.number,
                lot.id,
                *lot.entry,
                *lot.exit,
                lot.time_s,
                lot.area_m2,
                lot.gain_s,
                sorted(bidders),
            )
            self.publish(self.keys.task(lot.id), call, True)
        deadline = time.monotonic() + self.params.bid_timeout_s
        want = len(rnd.lots) * len(bidders)
        with self._cond:
            while len(rnd.bids) < want and not self.stop.is_set():
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
        """The round's best bid among those of robots still in ``market`` (and, with
        ``allowed``, that may win the lot they bid on) wins: the sale, also reported to
        ``on_sale``; None (and a warning) if no such robot bid."""
        live = [
            b
            for b in rnd.bids.values()
            if b.robot in market
            and not b.declined
            and (allowed is None or allowed(rnd.lots[b.task], b.robot))
        ]
        best = auction.winner(
            auction.Bid(b.task, b.robot, b.marginal_s, b.total_s, b.reverse) for b in live
        )
        if best is None and rnd.bids:
            log.info(
                "auction round %d: %d bid(s), none may win (its robot left the market, its lot "
                "changed meanwhile, its robot tried it, or declined it on its charge)",
                rnd.number,
                len(rnd.bids),
            )
            return None
        if best is None:
            log.warning(
                "auction round %d: no bids from %s within %.1f s",
                rnd.number,
                ", ".join(sorted(rnd.bidders)),
                self.params.bid_timeout_s,
            )
            return None
        sale = Sale(rnd.number, rnd.lots[best.task], best, live)
        self.on_sale(sale)
        return sale
