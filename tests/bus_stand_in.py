"""Stand-ins for a process's bus, for tests that drive a server's handlers or an agent's control
step directly: :class:`NoBus` subscribes and serves nothing and records what the server drops
as implausible; :class:`LoopbackBus` hands an agent's publications to the test; :func:`answer`
is a robot's answer to an auction call at one price for every lot."""

from __future__ import annotations

import numpy as np

from fleet.protocol import AuctionCall, Bids, Keys, Message


def answer(call: AuctionCall, robot: str, price: float, declined: bool = False) -> Bids:
    """``robot``'s bids on every lot of ``call``: ``price`` seconds marginal and total, each
    entered at its entry (and all ``declined``, when asked)."""
    k = len(call.lots)
    return Bids(
        call.stamp,
        call.round,
        robot,
        list(call.lots),
        np.full(k, float(price)),
        np.full(k, float(price)),
        np.zeros(k, dtype=np.uint8),
        np.full(k, int(declined), dtype=np.uint8),
    )


class NoBus:
    keys = Keys()

    def __init__(self) -> None:
        self.dropped: list[tuple[str, str, str]] = []

    def subscribe(self, *_args: object) -> None:
        return None

    def serve(self, *_args: object) -> None:
        return None

    def watch_alive(self, *_args: object) -> None:
        return None

    def drop_implausible(self, key: str, sender: str, why: str, n: int = 1) -> None:
        self.dropped.append((key, sender, why))


class LoopbackBus:
    """What an agent's control step needs of :class:`fleet.bus.Bus`: its publications are
    handed to the test (intents to the other agents, commands to the simulator)."""

    def __init__(self, keys: Keys, deliver: dict[str, list[tuple[str, Message]]]) -> None:
        self.keys = keys
        self.decode_errors: dict[str, int] = {}
        self._deliver = deliver
        self.implausible = 0

    def publish(self, key: str, msg: Message, control: bool = False) -> None:
        self._deliver.setdefault(type(msg).__name__, []).append((key, msg))

    def drop_implausible(self, key: str, sender: str, why: str, n: int = 1) -> None:
        self.implausible += n

    def dropped(self) -> tuple[int, int]:
        return sum(self.decode_errors.values()), self.implausible
