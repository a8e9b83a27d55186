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
        # A* reads single cells: Python lists are several times faster at that than numpy
        self._free_rows = free.tolist()
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
        free = self._free_rows
        rows, cols = self.free.shape

        def h(r: int, c: int) -> float:
            dr, dc = abs(r - g[0]), abs(c - g[1])
            return max(dr, dc) + (_SQRT2 - 1) * min(dr, dc)

        best = {s: 0.0}
        parent: dict[tuple[int, int], tuple[int, int]] = {}
        heap = [(h(*s), 0.0, s)]
        closed = set()
        while heap:
            _, cost, cur = heapq.heappop(heap)
            if cur == g:
                out = [cur]
                while out[-1] in parent:
                    out.append(parent[out[-1]])
                return out[::-1]
            if cur in closed:
                continue
            closed.add(cur)
            r, c = cur
            for dr, dc in _MOVES:
                nr, nc = r + dr, c + dc
                if not (0 <= nr < rows and 0 <= nc < cols) or not free[nr][nc]:
                    continue
                if dr and dc and not (free[r][nc] and free[nr][c]):
                    continue
                nxt = (nr, nc)
                step = _SQRT2 if dr and dc else 1.0
                ncost = cost + step
                if ncost < best.get(nxt, math.inf):
                    best[nxt] = ncost
                    parent[nxt] = cur
                    heapq.heappush(heap, (ncost + h(nr, nc), ncost, nxt))
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
