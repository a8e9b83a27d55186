"""Heartbeats noted as they arrive, whoever holds the coordinator's lock.

On a large floor the coordinator's main loop holds its lock for a second or more (the first
plans sent, a lost robot's many tasks reopened). Heartbeats that waited for the lock counted
as silence: on the recorded apartment every robot was lost within 10 s of the start, one after
the other (each loss holding the lock for seconds more), and the whole first allocation was
sold again lot by lot. So a heartbeat's arrival is noted here without the lock, and applied
(judged plausible, the robot's time of last hearing set to it) with the lock, by the receiver
when the lock is free or by the main loop before it judges who is silent.
"""

from __future__ import annotations

import time

from fleet.protocol import Heartbeat


class Beats:
    """The heartbeats heard and not yet applied: per key, the last one and its arrival."""

    def __init__(self) -> None:
        self._pending: dict[str, tuple[float, Heartbeat]] = {}

    def note(self, key: str, msg: Heartbeat) -> None:
        """``msg`` heard on ``key`` now (no lock needed: one dict item set)."""
        self._pending[key] = (time.time(), msg)

    def take(self) -> list[tuple[str, float, Heartbeat]]:
        """The beats noted since the last call, (key, wall time heard, beat), each once."""
        return [(key, *self._pending.pop(key)) for key in list(self._pending)]
