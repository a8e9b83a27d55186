"""Transit paths between sweeps: straight where the line is clear, else A* on the free centres.

A* (Hart, Nilsson, Raphael 1968) on the 8-connected grid of cells a robot centre may occupy
(the map inflated by the robot radius), with the octile-distance heuristic and no diagonal step
past a blocked corner; the cell path is then shortened by line-of-sight string pulling.
"""

from __future__ import annotations

import heapq
import math

import numpy as np
from scipy import ndimage

from planners.grid import GridMap

_SQRT2 = math.sqrt(2.0)
_MOVES = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


class Transit:
    """Plans transits on one grid; ``free`` is the set of cells a robot centre may occupy."""

    def __init__(self, grid: GridMap, free: np.ndarray) -> None:
        self.grid = grid
        self.free = free
        _, idx = ndimage.distance_transform_edt(~free, return_indices=True)
        self._nearest = idx
        # A* reads single cells by flat index into the grid padded by one blocked cell all
        # round (no bounds checks); Python lists are several times faster at that than numpy
        self._width = free.shape[1] + 2
        self._free_flat = np.pad(free, 1).ravel().tolist()
        # the tour is driven several times (fill-in rounds, pruning), mostly over the same hops
        self._planned: dict[tuple[float, ...], np.ndarray] = {}

    def snap(self, xy: np.ndarray) -> tuple[int, int]:
        """The free cell holding ``xy``, or the nearest free cell to it."""
        rc = self.grid.world_to_cell(np.asarray(xy, dtype=float))
        rows, cols = self.free.shape
        r = int(np.clip(rc[0], 0, rows - 1))
        c = int(np.clip(rc[1], 0, cols - 1))
        return int(self._nearest[0, r, c]), int(self._nearest[1, r, c])

    def clear(self, a: np.ndarray, b: np.ndarray) -> bool:
        """Whether every cell the segment a–b passes through (sampled at ⅓ cell) is free."""
        res = self.grid.resolution
        ox, oy = self.grid.origin
        n = math.ceil(3 * math.hypot(b[0] - a[0], b[1] - a[1]) / res) + 1
        t = np.linspace(0.0, 1.0, max(2, n))
        col = np.floor((a[0] + (b[0] - a[0]) * t - ox) / res).astype(np.intp)
        row = np.floor((a[1] + (b[1] - a[1]) * t - oy) / res).astype(np.intp)
        rows, cols = self.free.shape
        # samples along a segment are monotone in row and column: its ends bound them
        if min(row[0], row[-1]) < 0 or min(col[0], col[-1]) < 0:
            return False
        if max(row[0], row[-1]) >= rows or max(col[0], col[-1]) >= cols:
            return False
        return bool(self.free[row, col].all())

    def path(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(N, 2) world path from ``a`` to ``b`` through free cells (endpoints included; a
        read-only array, shared by later calls for the same ends)."""
        a = np.asarray(a, dtype=float)
        b = np.asarray(b, dtype=float)
        key = (*a.tolist(), *b.tolist())
        if key not in self._planned:
            path = self._plan(a, b)
            path.setflags(write=False)
            self._planned[key] = path
        return self._planned[key]

    def _plan(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        if self.clear(a, b):
            return np.array([a, b])
        cells = self.astar(self.snap(a), self.snap(b))
        if cells is None:
            raise ValueError(f"no free path from {a.tolist()} to {b.tolist()}")
        pts = np.vstack([a, self.grid.cell_to_world(np.array(cells)), b])
        return self._pull(pts)

    def astar(self, s: tuple[int, int], g: tuple[int, int]) -> list[tuple[int, int]] | None:
        """The cell path from ``s`` to ``g`` (both included), or None when none is free.

        Cells are flat indices into the padded grid, which order as (row, col) pairs do, so the
        heap breaks ties as it would on the pairs."""
        free = self._free_flat
        w = self._width
        gr, gc = g[0] + 1, g[1] + 1
        goal = gr * w + gc
        # (index step, cost, the two side cells a diagonal step must not cut between)
        moves = [(dr * w + dc, _SQRT2 if dr and dc else 1.0, dc, dr * w) for dr, dc in _MOVES]
        diag = _SQRT2 - 1

        def h(i: int) -> float:
            r, c = divmod(i, w)
            dr, dc = abs(r - gr), abs(c - gc)
            return dr + diag * dc if dr > dc else dc + diag * dr

        first = (s[0] + 1) * w + s[1] + 1
        best = {first: 0.0}
        parent: dict[int, int] = {}
        heap = [(h(first), 0.0, first)]
        closed = set()
        push, pop, inf = heapq.heappush, heapq.heappop, math.inf
        while heap:
            _, cost, cur = pop(heap)
            if cur == goal:
                out = [cur]
                while out[-1] in parent:
                    out.append(parent[out[-1]])
                return [((i // w) - 1, (i % w) - 1) for i in reversed(out)]
            if cur in closed:
                continue
            closed.add(cur)
            for step, length, side_c, side_r in moves:
                nxt = cur + step
                if not free[nxt]:
                    continue
                if side_r and side_c and not (free[cur + side_c] and free[cur + side_r]):
                    continue
                ncost = cost + length
                if ncost < best.get(nxt, inf):
                    best[nxt] = ncost
                    parent[nxt] = cur
                    r, c = divmod(nxt, w)
                    dr, dc = abs(r - gr), abs(c - gc)
                    est = dr + diag * dc if dr > dc else dc + diag * dr
                    push(heap, (ncost + est, ncost, nxt))
        return None

    def _pull(self, pts: np.ndarray) -> np.ndarray:
        """Keep only the points needed for line of sight (greedy string pulling)."""
        out = [pts[0]]
        i = 0
        n = len(pts)
        while i < n - 1:
            j = n - 1
            while j > i + 1 and not self.clear(pts[i], pts[j]):
                j = max(i + 1, i + (j - i) // 2)
            out.append(pts[j])
            i = j
        return np.array(out)
