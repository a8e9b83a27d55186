"""Constraint / reservation tables (hard) and conflict-avoidance tables (soft) for low-level search.

Keys are ints: a vertex ``(cell, t)`` is ``t * n + cell``; a move ``u → v`` arriving at ``t`` is
``(t * n + u) * n + v``, where ``n`` is the number of grid cells.

Every low level that expands ``(cell, t)`` states under a constraint table (space-time and focal
A*, the joint search, MDDs, the earliest arrivals of corridor reasoning) asks the table for the
moves it allows (``ConstraintTable.moves``): one call per expansion. The table keeps, beside the
constraints, the states whose moves a constraint touches, so an expansion that no constraint
touches (most of them) gets the graph's successor tuple as it is, without a check per successor.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from planners.mapf.conflicts import positions

# no time: later than any time a search reaches
_NEVER = 1 << 62


class ConstraintTable:
    """Forbidden vertices, forbidden moves, cells blocked forever from some time on, and bounds on
    the time the agent reaches its goal for the last time (its cost).

    CBS fills it from a node's constraints; prioritized planning fills it with the paths of the
    higher-priority agents (a reservation table, Silver 2005), whose parked goals become
    ``blocked_from`` entries. The cost bounds are the length constraints of target reasoning
    (Li et al., AIJ 2021): ``min_finish`` (cost ≥ it) and ``max_finish`` (cost ≤ it, or None).
    """

    __slots__ = (
        "_calm",
        "_near",
        "_parked_pending",
        "_vertex_pending",
        "blocked_from",
        "edge",
        "horizon",
        "max_finish",
        "min_finish",
        "n",
        "vertex",
        "vertex_times",
    )

    def __init__(self, n: int) -> None:
        self.n = n
        self.vertex: set[int] = set()
        self.vertex_times: dict[int, list[int]] = {}
        self.edge: set[int] = set()
        self.blocked_from: dict[int, int] = {}
        self.min_finish = 0
        self.max_finish: int | None = None
        self.horizon = 0
        # states (t * n + cell) from which some move arriving at t is forbidden, and per cell
        # the first arrival time from which a successor is blocked for good (``moves``); the
        # vertex keys and parked cells added since ``moves`` last spread them to their neighbours
        self._near: set[int] = set()
        self._calm: list[int] | None = None
        self._vertex_pending: list[int] = []
        self._parked_pending: list[int] = []

    def add_vertex(self, cell: int, t: int) -> None:
        key = t * self.n + cell
        self.vertex.add(key)
        self._vertex_pending.append(key)
        self.vertex_times.setdefault(cell, []).append(t)
        if t > self.horizon:
            self.horizon = t

    def add_edge(self, u: int, v: int, t: int) -> None:
        """Forbid the move ``u → v`` that arrives at time ``t``."""
        self.edge.add((t * self.n + u) * self.n + v)
        self._near.add(t * self.n + u)
        self.horizon = max(self.horizon, t)

    def add_parked(self, cell: int, t: int) -> None:
        """``cell`` is occupied for every time ``≥ t``."""
        self.blocked_from[cell] = min(t, self.blocked_from.get(cell, t))
        self._parked_pending.append(cell)
        self.horizon = max(self.horizon, t)

    def add_min_finish(self, t: int) -> None:
        """The agent's cost must be at least ``t``: it may not stay at its goal for good before."""
        self.min_finish = max(self.min_finish, t)
        self.horizon = max(self.horizon, t)

    def add_max_finish(self, t: int) -> None:
        """The agent's cost must be at most ``t``: it is at its goal for good from ``t`` on."""
        self.max_finish = t if self.max_finish is None else min(self.max_finish, t)
        self.horizon = max(self.horizon, t)

    def reserve_path(self, path: Sequence[int]) -> None:
        """Reserve a higher-priority agent's path: cells, moves (against swaps), parked goal."""
        n = self.n
        last = len(path) - 1
        for t in range(last):
            self.add_vertex(path[t], t)
            # the move back, arriving at t + 1 (``add_edge``)
            key = (t + 1) * n + path[t + 1]
            self.edge.add(key * n + path[t])
            self._near.add(key)
        self.add_parked(path[last], last)

    def earliest_finish(self, goal: int) -> int | None:
        """First time an agent may stop at ``goal`` for good, or None if it never may."""
        if goal in self.blocked_from:
            return None
        times = self.vertex_times.get(goal)
        earliest = max(max(times) + 1 if times else 0, self.min_finish)
        if self.max_finish is not None and earliest > self.max_finish:
            return None
        return earliest

    def moves(self, successors: Sequence[Sequence[int]]) -> Callable[[int, int], Sequence[int]]:
        """``moves(cell, t)``: the cells among ``successors[cell]`` (the graph's successor lists:
        wait first, then the neighbours) that an agent in ``cell`` at ``t - 1`` may be in at
        ``t``: no vertex constraint there at t, not blocked for good by t, the move not
        forbidden. For the successor lists of one graph; valid until the table changes."""
        n = self.n
        near = self._near
        for key in self._vertex_pending:
            t, cell = divmod(key, n)
            tn = t * n
            near.update([tn + u for u in successors[cell]])
        self._vertex_pending.clear()
        if self._calm is None:
            self._calm = [_NEVER] * n
        calm = self._calm
        for cell in self._parked_pending:
            t = self.blocked_from[cell]
            for u in successors[cell]:
                if t < calm[u]:
                    calm[u] = t
        self._parked_pending.clear()
        vertex, edge, blocked = self.vertex, self.edge, self.blocked_from

        def admissible(cell: int, t: int) -> Sequence[int]:
            key = t * n + cell
            if key not in near and t < calm[cell]:
                return successors[cell]
            tn = t * n
            out = []
            for nc in successors[cell]:
                if tn + nc in vertex:
                    continue
                bf = blocked.get(nc)
                if bf is not None and t >= bf:
                    continue
                if nc != cell and key * n + nc in edge:
                    continue
                out.append(nc)
            return out

        return admissible


class ConflictAvoidanceTable:
    """How many other agents' paths a vertex or move collides with (Standley 2010's CAT).

    Used to break ties among equal-cost paths (CBS) and as the focal heuristic (ECBS). Built with
    numpy from a padded positions array: one sort instead of a Python loop over every step.
    """

    __slots__ = ("edge", "horizon", "n", "parked", "vertex")

    def __init__(
        self,
        n: int,
        vertex: dict[int, int],
        edge: dict[int, int],
        parked: dict[int, int],
        horizon: int,
    ) -> None:
        self.n = n
        self.vertex = vertex
        self.edge = edge
        self.parked = parked
        self.horizon = horizon

    @classmethod
    def from_paths(cls, n: int, paths: Sequence[Sequence[int]]) -> ConflictAvoidanceTable:
        if not paths:
            return cls(n, {}, {}, {}, 0)
        return cls.from_positions(n, positions(paths), [len(p) for p in paths], -1)

    @classmethod
    def from_positions(
        cls, n: int, pos: np.ndarray, lengths: Sequence[int], exclude: int | Sequence[int]
    ) -> ConflictAvoidanceTable:
        """The table of every row of ``pos`` (paths padded with their last cell) but ``exclude``
        (one row, or several: the members of a meta-agent).

        A path of length L occupies ``(pos[t], t)`` for t < L - 1 and is parked at its last cell
        from ``L - 1`` on; its moves are recorded under the key of the reverse move (a swap).
        """
        k, horizon = pos.shape
        last = np.asarray(lengths, dtype=np.int64) - 1
        keep = ~np.isin(np.arange(k), exclude)
        t = np.arange(horizon, dtype=np.int64)[None, :]
        moving = t < last[:, None]
        v_mask = moving & keep[:, None]
        vkeys, vcounts = np.unique((t * n + pos)[v_mask], return_counts=True)
        frm, to = pos[:, :-1], pos[:, 1:]
        e_mask = v_mask[:, :-1] & (frm != to)
        ekeys, ecounts = np.unique((((t[:, 1:]) * n + to) * n + frm)[e_mask], return_counts=True)
        rows = np.nonzero(keep)[0]
        parked = dict(zip(pos[rows, last[rows]].tolist(), last[rows].tolist(), strict=True))
        return cls(
            n,
            dict(zip(vkeys.tolist(), vcounts.tolist(), strict=True)),
            dict(zip(ekeys.tolist(), ecounts.tolist(), strict=True)),
            parked,
            int(last[rows].max()) if len(rows) else 0,
        )
