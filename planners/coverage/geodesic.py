"""Path-cost estimates between many points of the floor, for ordering tasks.

Straight-line distance misjudges hops that have to go round a wall or through a door; planning
an A* transit for every pair of task ends is too slow. Instead Dijkstra runs on a coarse copy of
the robot-centre grid (blocks of about ``COARSE_M``, a block free when any of its cells is):
every point snaps to its block, and the estimate for a pair is the larger of the straight-line
distance and the coarse 8-connected path length divided by 1.04 (the midpoint of the 1–1.082
factor by which an 8-connected grid path overestimates the Euclidean one). Dijkstra from each
point stops at ``NEAR_M``; a farther pair is priced through landmarks — ``LANDMARKS`` blocks
spread by farthest-point sampling, each with a full Dijkstra — as the least d(a, l) + d(l, b)
(an upper bound, tight when some landmark lies near the way, e.g. in a door on it).
Distances between blocks already asked for are kept, so a second, larger set of points costs
only the new blocks.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage
from scipy.sparse.csgraph import dijkstra
from scipy.spatial.distance import cdist

from planners.coverage.rooms import grid_graph
from planners.grid import GridMap

COARSE_M = 0.1
NEAR_M = 4.0
LANDMARKS = 64
_OCTILE_BIAS = 1.04
_CHUNK = 64
_UNREACHABLE = 1e6


class PathCosts:
    """Path-cost estimates for a robot centre confined to ``free`` (a grid-shaped mask)."""

    def __init__(self, grid: GridMap, free: np.ndarray) -> None:
        self.grid = grid
        self.f = max(1, round(COARSE_M / grid.resolution))
        rows, cols = math.ceil(free.shape[0] / self.f), math.ceil(free.shape[1] / self.f)
        padded = np.zeros((rows * self.f, cols * self.f), dtype=bool)
        padded[: free.shape[0], : free.shape[1]] = free
        coarse = padded.reshape(rows, self.f, cols, self.f).any(axis=(1, 3))
        graph, self._index = grid_graph(coarse)
        self._csr = graph.tocsr()
        _, self._near = ndimage.distance_transform_edt(~coarse, return_indices=True)
        self._nodes = np.zeros(0, dtype=np.int64)
        self._geo = np.zeros((0, 0))
        self._landmarks = self._landmark_rows()

    def _landmark_rows(self) -> np.ndarray:
        """(K, nodes) coarse path lengths from landmarks spread by farthest-point sampling
        (per connected part: an unreached node is infinitely far from every landmark so far)."""
        n = self._csr.shape[0]
        if n == 0:
            return np.zeros((0, 0))
        rows = []
        nearest = np.full(n, np.inf)
        node = 0
        for _ in range(min(LANDMARKS, n)):
            d = dijkstra(self._csr, indices=node)
            rows.append(d)
            nearest = np.minimum(nearest, d)
            node = int(np.argmax(nearest))
            if nearest[node] == 0:
                break
        return np.array(rows)

    def matrix(self, points: np.ndarray) -> np.ndarray:
        """(N, N) symmetric cost estimates (metres) between world ``points`` (N, 2); pairs in
        different components get a large finite cost."""
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        euclid = cdist(pts, pts)
        if len(pts) == 0 or self._csr.shape[0] == 0:
            return euclid
        shape = np.array(self._index.shape) - 1
        rc = np.clip(self.grid.world_to_cell(pts) // self.f, 0, shape)
        near_r = self._near[0, rc[:, 0], rc[:, 1]]
        near_c = self._near[1, rc[:, 0], rc[:, 1]]
        node = self._index[near_r, near_c]
        self._add(np.setdiff1d(node, self._nodes))
        pos = np.searchsorted(self._nodes, node)
        geo = self._geo[np.ix_(pos, pos)]
        return np.maximum(euclid, geo)

    def _add(self, new: np.ndarray) -> None:
        """Extend the kept block-to-block costs by the blocks ``new``."""
        if len(new) == 0:
            return
        nodes = np.concatenate([self._nodes, new])
        rows = np.empty((len(new), len(nodes)))
        limit = NEAR_M / (self.f * self.grid.resolution)
        lm_new = self._landmarks[:, new]
        lm_all = self._landmarks[:, nodes]
        for k in range(0, len(new), _CHUNK):
            near = dijkstra(self._csr, indices=new[k : k + _CHUNK], limit=limit)[:, nodes]
            if len(lm_new) and not np.isfinite(near).all():
                # one landmark at a time: the (landmarks, chunk, nodes) sum would not fit a cache
                via = np.full(near.shape, np.inf)
                for from_new, from_all in zip(lm_new[:, k : k + _CHUNK], lm_all, strict=True):
                    np.minimum(via, from_new[:, None] + from_all[None, :], out=via)
                near = np.where(np.isfinite(near), near, via)
            rows[k : k + _CHUNK] = near
        scale = self.f * self.grid.resolution / _OCTILE_BIAS
        rows = np.where(np.isfinite(rows), rows * scale, _UNREACHABLE)
        n_old = len(self._nodes)
        # a search from each end sums the same path in another order: keep the costs exactly
        # symmetric, as the tour's local search reads a hop from either end
        fresh = rows[:, n_old:]
        rows[:, n_old:] = np.minimum(fresh, fresh.T)
        geo = np.empty((len(nodes), len(nodes)))
        geo[:n_old, :n_old] = self._geo
        geo[n_old:, :] = rows
        geo[:n_old, n_old:] = rows[:, :n_old].T
        order = np.argsort(nodes)
        self._nodes = nodes[order]
        self._geo = geo[np.ix_(order, order)]
