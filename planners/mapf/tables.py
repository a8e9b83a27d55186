"""Constraint / reservation tables (hard) and conflict-avoidance tables (soft) for low-level search.

Keys are ints: a vertex ``(cell, t)`` is ``t * n + cell``; a move ``u → v`` arriving at ``t`` is
``(t * n + u) * n + v``, where ``n`` is the number of grid cells.
"""

from __future__ import annotations

from collections.abc import Sequence


class ConstraintTable:
    """Forbidden vertices, forbidden moves, and cells blocked forever from some time on.

    CBS fills it from a node's constraints; prioritized planning fills it with the paths of the
    higher-priority agents (a reservation table, Silver 2005), whose parked goals become
    ``blocked_from`` entries.
    """

    __slots__ = ("blocked_from", "edge", "horizon", "n", "vertex", "vertex_times")

    def __init__(self, n: int) -> None:
        self.n = n
        self.vertex: set[int] = set()
        self.vertex_times: dict[int, list[int]] = {}
        self.edge: set[int] = set()
        self.blocked_from: dict[int, int] = {}
        self.horizon = 0

    def add_vertex(self, cell: int, t: int) -> None:
        self.vertex.add(t * self.n + cell)
        self.vertex_times.setdefault(cell, []).append(t)
        self.horizon = max(self.horizon, t)

    def add_edge(self, u: int, v: int, t: int) -> None:
        """Forbid the move ``u → v`` that arrives at time ``t``."""
        self.edge.add((t * self.n + u) * self.n + v)
        self.horizon = max(self.horizon, t)

    def add_parked(self, cell: int, t: int) -> None:
        """``cell`` is occupied for every time ``≥ t``."""
        self.blocked_from[cell] = min(t, self.blocked_from.get(cell, t))
        self.horizon = max(self.horizon, t)

    def reserve_path(self, path: Sequence[int]) -> None:
        """Reserve a higher-priority agent's path: cells, moves (against swaps), parked goal."""
        n = self.n
        last = len(path) - 1
        for t in range(last):
            self.add_vertex(path[t], t)
            self.edge.add(((t + 1) * n + path[t + 1]) * n + path[t])
        self.add_parked(path[last], last)

    def earliest_finish(self, goal: int) -> int | None:
        """First time an agent may stop at ``goal`` for good, or None if it never may."""
        if goal in self.blocked_from:
            return None
        times = self.vertex_times.get(goal)
        return max(times) + 1 if times else 0


class ConflictAvoidanceTable:
    """How many other agents' paths a vertex or move collides with (Standley 2010's CAT).

    Used to break ties among equal-cost paths (CBS) and as the focal heuristic (ECBS).
    """

    __slots__ = ("edge", "horizon", "n", "parked", "vertex")

    def __init__(self, n: int, paths: Sequence[Sequence[int]]) -> None:
        self.n = n
        vertex: dict[int, int] = {}
        edge: dict[int, int] = {}
        parked: dict[int, int] = {}
        horizon = 0
        for path in paths:
            last = len(path) - 1
            horizon = max(horizon, last)
            prev = path[0]
            for t in range(last):
                key = t * n + path[t]
                vertex[key] = vertex.get(key, 0) + 1
                cur = path[t + 1]
                if cur != prev:
                    ekey = ((t + 1) * n + cur) * n + prev
                    edge[ekey] = edge.get(ekey, 0) + 1
                prev = cur
            parked[path[last]] = last
        self.vertex = vertex
        self.edge = edge
        self.parked = parked
        self.horizon = horizon
