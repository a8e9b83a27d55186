"""The grid as a graph of int cells (``row * cols + col``) with cached true-distance heuristics.

Distances are exact 4-connected shortest-path lengths from each goal (a BFS, run in C by
``scipy.sparse.csgraph.shortest_path(unweighted=True)`` for many goals at once), the standard
admissible and consistent heuristic for grid MAPF.

By default every two 4-adjacent free cells are joined; ``open_right`` and ``open_down`` (boolean
masks of the moves to the right and down neighbour) can close some of those moves, for graphs
whose cells touch without a way between them (``planners.transit_graph``).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import shortest_path

from planners.mapf.model import Cell

UNREACHABLE = 1 << 30


class GridGraph:
    """Successor lists (wait first, then the free 4-neighbours) and per-goal distance tables."""

    def __init__(
        self,
        free: np.ndarray,
        open_right: np.ndarray | None = None,
        open_down: np.ndarray | None = None,
    ) -> None:
        """``open_right`` (rows, cols - 1) and ``open_down`` (rows - 1, cols), when given, say
        which moves between 4-adjacent free cells exist (both directions); None: all of them."""
        free = np.asarray(free, dtype=bool)
        self.rows, self.cols = free.shape
        self.num_cells = self.rows * self.cols
        self.free = free
        idx = np.arange(self.num_cells).reshape(free.shape)
        right = free[:, :-1] & free[:, 1:]
        down = free[:-1, :] & free[1:, :]
        if open_right is not None:
            if np.shape(open_right) != right.shape:
                raise ValueError(f"open_right must have shape {right.shape}")
            right &= np.asarray(open_right, dtype=bool)
        if open_down is not None:
            if np.shape(open_down) != down.shape:
                raise ValueError(f"open_down must have shape {down.shape}")
            down &= np.asarray(open_down, dtype=bool)
        a = np.concatenate([idx[:, :-1][right], idx[:-1, :][down]])
        b = np.concatenate([idx[:, 1:][right], idx[1:, :][down]])
        self._adjacency = coo_matrix(
            (np.ones(a.size), (a, b)), shape=(self.num_cells, self.num_cells)
        ).tocsr()
        neighbours: list[list[int]] = [[] for _ in range(self.num_cells)]
        for u, v in zip(a.tolist(), b.tolist(), strict=False):
            neighbours[u].append(v)
            neighbours[v].append(u)
        self.neighbours: list[tuple[int, ...]] = [tuple(sorted(n)) for n in neighbours]
        self.successors: list[tuple[int, ...]] = [
            (c, *n) if free.flat[c] else () for c, n in enumerate(self.neighbours)
        ]
        self._distances: dict[int, list[int]] = {}

    def cell(self, rc: Cell) -> int:
        return rc[0] * self.cols + rc[1]

    def rc(self, cell: int) -> Cell:
        return divmod(cell, self.cols)

    def precompute(self, goals: Iterable[int]) -> None:
        """BFS from all goals not yet cached, in one call."""
        todo = sorted({g for g in goals if g not in self._distances})
        if not todo:
            return
        dist = shortest_path(self._adjacency, directed=False, unweighted=True, indices=todo)
        dist = np.atleast_2d(dist)
        table = np.where(np.isfinite(dist), dist, UNREACHABLE).astype(np.int64)
        for goal, row in zip(todo, table, strict=False):
            self._distances[goal] = row.tolist()

    def distances(self, goal: int) -> list[int]:
        """Shortest-path length from every cell to ``goal`` (UNREACHABLE where none exists)."""
        if goal not in self._distances:
            self.precompute([goal])
        return self._distances[goal]
