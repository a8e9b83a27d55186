"""A wall-clock deadline that searches poll cheaply (every few hundred expansions)."""

from __future__ import annotations

import time

from planners.mapf.model import SearchTimeout


class Deadline:
    """``check()`` raises SearchTimeout once ``time_limit_s`` has passed since construction."""

    __slots__ = ("end", "start")

    def __init__(self, time_limit_s: float) -> None:
        self.start = time.perf_counter()
        self.end = self.start + max(0.0, time_limit_s)

    def check(self) -> None:
        if time.perf_counter() > self.end:
            raise SearchTimeout

    def elapsed(self) -> float:
        return time.perf_counter() - self.start
