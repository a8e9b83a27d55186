"""Travel-time estimates for bids: geodesic distance on an occupancy grid over a speed.

The grid is coarsened to at most ``COARSE_M`` per cell (a block is free only if all its cells
are), free blocks are the nodes of a 16-connected graph (the 8 neighbours and the 8 knight's
moves; a step only where every block of the rectangle it spans is free, so it never cuts a
blocked corner) with edges as long as the steps, and Dijkstra's algorithm
(``scipy.sparse.csgraph.dijkstra``) gives the distance from the start to every block. Grid
paths run along 16 headings only, so they are up to 2.7 % longer than the straight line (8 %
with 8 neighbours); a target in line of sight of the start (every block along the segment
free; an end in a blocked block is moved to the centre of its nearest free one) gets the
straight-line distance instead.

A start outside the grid or in a blocked block is moved to the nearest free block (Euclidean
distance transform with ``return_indices``); so is a target within ``TARGET_SNAP_M`` of a free
block (lane ends lie on the border of the inflated obstacles, which coarsening can close). A
target farther in an obstacle, or cut off from the start, gets the straight-line distance times
``UNREACHABLE_FACTOR``: a bid on it still exists, and it is priced as far away.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from planners.grid import GridMap, dilate

# coarsest cell the graph search keeps unchanged (m); finer grids are coarsened to about this
COARSE_M = 0.1
# a blocked or cut-off target costs its straight-line distance times this
UNREACHABLE_FACTOR = 3.0
# a blocked target this close (m) to a free block is priced at that block
TARGET_SNAP_M = 0.3
# distance arrays kept per TravelGrid (one per start block, the oldest dropped first)
CACHE_STARTS = 32

# steps of the graph search: 16 headings, whose longest detour over the straight line is 2.7 %
_STEPS = ((0, 1), (1, 0), (1, 1), (1, -1), (1, 2), (2, 1), (1, -2), (2, -1))


class TravelGrid:
    """Travel-time estimates on one occupancy grid at one speed (the module docstring tells
    how): build once per map, call for every bid. The coarse graph is built once; the distances
    from a start block are kept for the next calls from the same block."""

    def __init__(
        self,
        free: np.ndarray,
        resolution: float,
        origin: tuple[float, float],
        speed: float,
    ) -> None:
        if not speed > 0:
            raise ValueError(f"speed must be > 0, got {speed}")
        if not resolution > 0:
            raise ValueError(f"resolution must be > 0, got {resolution}")
        free = np.asarray(free, dtype=bool)
        if free.ndim != 2:
            raise ValueError(f"free must be a 2-D grid, got shape {free.shape}")
        factor = max(1, math.floor(COARSE_M / resolution + 1e-9))
        rows, cols = -(-free.shape[0] // factor), -(-free.shape[1] // factor)
        padded = np.zeros((rows * factor, cols * factor), dtype=bool)
        padded[: free.shape[0], : free.shape[1]] = free
        self.free = padded.reshape(rows, factor, cols, factor).all(axis=(1, 3))
        self.cell = resolution * factor
        self.origin = (float(origin[0]), float(origin[1]))
        self.speed = float(speed)
        self._graph = _graph(self.free)
        # (2, rows, cols): the (row, col) of the nearest free block of every block
        self._nearest = ndimage.distance_transform_edt(~self.free, return_indices=True)[1]
        self._cache: dict[int, np.ndarray] = {}

    def __call__(self, start_xy: np.ndarray, targets_xy: np.ndarray) -> np.ndarray:
        """Estimated seconds from ``start_xy`` (2,) to each of ``targets_xy`` (K, 2)."""
        start = np.asarray(start_xy, dtype=float).reshape(2)
        targets = np.asarray(targets_xy, dtype=float).reshape(-1, 2)
        straight = np.hypot(*(targets - start).T)
        far = straight * UNREACHABLE_FACTOR / self.speed
        if not self.free.any() or len(targets) == 0:
            return far
        cols = self.free.shape[1]
        start_rc = self._cell_of(start[None, :])
        src = self._snapped(start_rc)
        dist = self._distances(int(src[0, 0] * cols + src[0, 1]))
        rc = self._cell_of(targets)
        snapped = self._snapped(rc)
        near = np.hypot(*(snapped - rc).T) * self.cell <= TARGET_SNAP_M
        geo = dist[snapped[:, 0] * cols + snapped[:, 1]] * self.cell
        # sight lines run between free points: an end in a blocked block moves to its free one
        seen = self._in_sight(
            self._free_point(start[None, :], start_rc, src)[0],
            self._free_point(targets, rc, snapped),
        )
        metres = np.where(seen, straight, geo)
        return np.where(near & (seen | np.isfinite(geo)), metres / self.speed, far)

    def _cell_of(self, xy: np.ndarray) -> np.ndarray:
        col = np.floor((xy[:, 0] - self.origin[0]) / self.cell).astype(np.int64)
        row = np.floor((xy[:, 1] - self.origin[1]) / self.cell).astype(np.int64)
        return np.stack([row, col], axis=1)

    def _snapped(self, rc: np.ndarray) -> np.ndarray:
        """The nearest free block of each (row, col), clipped into the grid first."""
        rows, cols = self.free.shape
        r = np.clip(rc[:, 0], 0, rows - 1)
        c = np.clip(rc[:, 1], 0, cols - 1)
        return np.stack([self._nearest[0][r, c], self._nearest[1][r, c]], axis=1)

    def _distances(self, node: int) -> np.ndarray:
        """Geodesic distances (blocks) from ``node`` to every block, inf where cut off."""
        if node not in self._cache:
            if len(self._cache) >= CACHE_STARTS:
                del self._cache[next(iter(self._cache))]
            self._cache[node] = dijkstra(self._graph, directed=False, indices=node)
        return self._cache[node]

    def _free_point(self, xy: np.ndarray, rc: np.ndarray, snapped: np.ndarray) -> np.ndarray:
        """Each point, or the centre of its snapped block where that is another block."""
        centres = (snapped[:, ::-1] + 0.5) * self.cell + self.origin
        return np.where((rc == snapped).all(axis=1)[:, None], xy, centres)

    def _in_sight(self, start: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """Whether every block along the segment from ``start`` (2,) to each of ``targets``
        (K, 2) is free, each segment sampled every half block of its own length at most."""
        if not len(targets):
            return np.zeros(0, dtype=bool)
        length = np.hypot(*(targets - start).T)
        n = np.maximum(2, np.ceil(length / (self.cell / 2)).astype(np.int64) + 1)
        first = np.cumsum(n) - n
        seg = np.repeat(np.arange(len(targets)), n)
        frac = (np.arange(int(n.sum())) - first[seg]) / (n[seg] - 1)
        pts = start + frac[:, None] * (targets - start)[seg]
        rc = self._cell_of(pts)
        rows, cols = self.free.shape
        inside = (rc[:, 0] >= 0) & (rc[:, 0] < rows) & (rc[:, 1] >= 0) & (rc[:, 1] < cols)
        ok = np.zeros(len(rc), dtype=bool)
        ok[inside] = self.free[rc[inside, 0], rc[inside, 1]]
        return np.logical_and.reduceat(ok, first)


def travel_times(
    free: np.ndarray,
    resolution: float,
    origin: tuple[float, float],
    start_xy: np.ndarray,
    targets_xy: np.ndarray,
    speed: float,
) -> np.ndarray:
    """Estimated seconds from ``start_xy`` to each of ``targets_xy`` (K, 2) on the grid ``free``
    (True where a robot may drive: the caller's map with unknown cells counted as free and
    obstacles inflated), at ``speed``: :class:`TravelGrid` built for one call."""
    return TravelGrid(free, resolution, origin, speed)(start_xy, targets_xy)


def floor_travel(floor: GridMap, radius: float, speed: float) -> TravelGrid:
    """Travel times on a floor plan as robots price them and the coordinator checks them: its
    occupied and unknown cells grown by the robot's ``radius``, at ``speed``."""
    blocked = dilate(floor.occupied | floor.unknown, radius, floor.resolution)
    return TravelGrid(~blocked, floor.resolution, floor.origin, speed)


def _graph(free: np.ndarray) -> csr_matrix:
    """The 16-connected graph of the free blocks (node = row · cols + col), each edge once: a
    step is an edge when every block of the rectangle spanned by its two ends is free (none
    longer than the grid: an exploring fleet's map starts a block wide)."""
    rows, cols = free.shape
    ids = np.arange(rows * cols).reshape(rows, cols)
    heads, tails, weights = [np.zeros(0, int)], [np.zeros(0, int)], [np.zeros(0)]
    for dr, dc in _STEPS:
        if dr >= rows or abs(dc) >= cols:
            continue
        span = np.ones((rows - dr, cols - abs(dc)), dtype=bool)
        for i in range(dr + 1):
            for j in range(abs(dc) + 1):
                span &= free[i : rows - dr + i, j : cols - abs(dc) + j]
        # the rectangle's corners: (r, c) → (r + dr, c + dc) for dc >= 0, mirrored for dc < 0
        a = ids[: rows - dr, : cols - abs(dc)] + (abs(dc) if dc < 0 else 0)
        heads.append(a[span])
        tails.append(a[span] + dr * cols + dc)
        weights.append(np.full(int(span.sum()), math.hypot(dr, dc)))
    n = rows * cols
    return csr_matrix(
        (np.concatenate(weights), (np.concatenate(heads), np.concatenate(tails))), shape=(n, n)
    )
