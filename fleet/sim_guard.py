"""Guards against a hang that judge by the sim clock, not by wall time alone.

A wait for something that happens in sim time (a job's end, a robot's loss, the sim clock at
a given time) cannot be bounded in wall seconds alone: on a starved machine the simulator steps
in lockstep with its agents, so the sim clock moves slowly, and a wall bound fires while the
run is well. A hung fleet is told apart by its clock, which stops.

:class:`SimGuard` gives up on such a wait only once it has lasted ``wall_s`` wall seconds
(never sooner than a wall bound would) *and*

- the sim clock has not moved for the last ``stall_s`` wall seconds (the fleet is hung, or its
  clock cannot be heard), or
- the sim clock has moved ``sim_s`` past where it stood when the wait began (what is awaited
  should have happened by then, however slowly the sim ran).

So past its wall bound a slow sim is waited for as long as it moves, up to a budget in sim
seconds, and a stopped one is not.
Wall time is the monotonic clock; both clocks are passed in, so the rule is tested without
processes.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable


class SimGuard:
    """One wait's guard; :meth:`expired` is asked at each poll of the wait."""

    def __init__(
        self,
        sim_now: Callable[[], float],
        wall_s: float,
        stall_s: float,
        sim_s: float = math.inf,
        wall_now: Callable[[], float] = time.monotonic,
    ) -> None:
        """``sim_now``: the sim time as the waiter hears it; ``wall_s``: the wall time the
        wait lasts at least; ``stall_s``: the wall time without a move of the sim clock that
        counts as stalled; ``sim_s``: the sim time the awaited thing may take (no bound by
        default: past ``wall_s``, only a stalled clock ends the wait)."""
        if wall_s < 0 or stall_s <= 0 or sim_s <= 0:
            raise ValueError(f"wall_s >= 0, stall_s > 0, sim_s > 0, not {wall_s, stall_s, sim_s}")
        self.sim_now = sim_now
        self.wall_now = wall_now
        self.wall_s = wall_s
        self.stall_s = stall_s
        self.sim_s = sim_s
        self.started = self.moved_at = wall_now()
        self.sim_start = self.sim_last = sim_now()

    def expired(self) -> bool:
        """Whether the wait should give up now (see the module docstring)."""
        now, sim = self.wall_now(), self.sim_now()
        if sim > self.sim_last:
            self.sim_last, self.moved_at = sim, now
        if now - self.started < self.wall_s:
            return False
        return now - self.moved_at >= self.stall_s or sim - self.sim_start >= self.sim_s

    def why(self) -> str:
        """What the guard saw, for the message of a wait that gave up."""
        now = self.wall_now()
        return (
            f"{now - self.started:.0f} s wall, the sim clock at {self.sim_last:.1f} s "
            f"({self.sim_last - self.sim_start:.1f} s on since the wait began, not moved for "
            f"{now - self.moved_at:.0f} s)"
        )
