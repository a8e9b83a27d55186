"""The robot's bid loop: each auction call answered with one message, on a thread of its own.

The coordinator calls a round's lots in one :class:`~fleet.protocol.AuctionCall` on
``coord/call`` (:mod:`fleet.coordinator.auctioneer`); the robot answers with one
:class:`~fleet.protocol.Bids` on ``coord/bids/<robot>``. Only the latest call is answered: one
that arrives while the robot prices the last replaces any older one still waiting, whose round
has closed by then (its answer would be counted late). Pricing happens off the bus's thread, so
a round of 500 lots never holds up the robot's other messages.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from fleet.bus import Bus
from fleet.protocol import AuctionCall, Bids


class Bidder:
    """Answers the calls it is handed (:meth:`on_call`, the subscriber of ``coord/call``) with
    ``answer(call)`` (None: no answer, e.g. a round that does not name the robot) until
    ``stop``; a call whose answer fails costs that round, never the loop."""

    def __init__(
        self,
        bus: Bus,
        robot: str,
        answer: Callable[[AuctionCall], Bids | None],
        stop: threading.Event,
    ) -> None:
        self.bus = bus
        self.robot = robot
        self.answer = answer
        self.stop = stop
        self.answered = 0
        self._call: AuctionCall | None = None
        self._ready = threading.Condition()

    def on_call(self, _key: str, msg: AuctionCall) -> None:
        with self._ready:
            if self._call is None or msg.round >= self._call.round:
                self._call = msg
            self._ready.notify()

    def loop(self) -> None:
        """Answer calls until ``stop``."""
        while not self.stop.is_set():
            with self._ready:
                if self._call is None:
                    self._ready.wait(0.1)
                    continue
                call, self._call = self._call, None
            try:
                bids = self.answer(call)
                if bids is not None:
                    self.bus.publish(self.bus.keys.bids(self.robot), bids, control=True)
                    self.answered += 1
            except Exception:
                self.bus.handler_failed("coord/call")
