"""Log-odds occupancy grid with vectorized ray updates (Thrun et al., Probabilistic Robotics §9.2).

Rays are sampled every ¾ cell with numpy, all beams at once (a cell that a ray only clips by a
shorter chord may be skipped; neighbouring beams cover it). As in Cartographer (Hess et al.
2016), a cell changes at most once per scan and a hit wins over a miss in the same scan, so cells
near the sensor are not driven to "free" by hundreds of rays at once.
"""

from __future__ import annotations

import math

import numpy as np


def log_odds(p: float) -> float:
    return math.log(p / (1.0 - p))


class LogOddsGrid:
    """A fixed-size grid in a local frame: cell (r, c) covers x ∈ [ox + c·res, ox + (c+1)·res),
    y ∈ [oy + r·res, oy + (r+1)·res) (row 0 = lowest y, as in ``planners.grid.GridMap``)."""

    def __init__(
        self,
        shape: tuple[int, int],
        origin: tuple[float, float],
        resolution: float,
        p_hit: float,
        p_miss: float,
        p_min: float,
        p_max: float,
    ) -> None:
        self.log_odds = np.zeros(shape, dtype=np.float32)
        self.origin = (float(origin[0]), float(origin[1]))
        self.resolution = float(resolution)
        self.l_hit = log_odds(p_hit)
        self.l_miss = log_odds(p_miss)
        self.l_min = log_odds(p_min)
        self.l_max = log_odds(p_max)
        self._mark = np.zeros(shape[0] * shape[1], dtype=bool)
        self.touched: tuple[int, int, int, int] | None = None  # row0, row1, col0, col1 (exclusive)

    @property
    def shape(self) -> tuple[int, int]:
        return self.log_odds.shape  # type: ignore[return-value]

    def to_cells(self, xy: np.ndarray) -> np.ndarray:
        """(..., 2) local points → (..., 2) float (row, col) cell coordinates."""
        col = (xy[..., 0] - self.origin[0]) / self.resolution
        row = (xy[..., 1] - self.origin[1]) / self.resolution
        return np.stack([row, col], axis=-1)

    def insert(
        self, sensor_xy: np.ndarray, endpoints: np.ndarray, misses: np.ndarray | None = None
    ) -> None:
        """Integrate one scan: ``endpoints`` (N, 2) are beam returns, ``misses`` (M, 2) the ends
        of rays that met nothing (free all the way, no hit), in this grid's frame."""
        misses = np.zeros((0, 2)) if misses is None else misses
        if endpoints.shape[0] == 0 and misses.shape[0] == 0:
            return
        rows, cols = self.shape
        ends = np.concatenate([endpoints, misses])
        delta = ends - sensor_xy
        length = np.hypot(delta[:, 0], delta[:, 1])
        step = 0.75 * self.resolution
        # a return's ray stops a cell short of its hit; a missing ray is free to its end
        free = length - np.where(np.arange(length.size) < endpoints.shape[0], self.resolution, 0.0)
        counts = np.ceil(np.maximum(free, 0.0) / step).astype(np.int64)
        beam = np.repeat(np.arange(counts.size), counts)
        first = np.repeat(np.cumsum(counts) - counts, counts)
        frac = (np.arange(beam.size) - first) * step / np.maximum(length, 1e-9)[beam]
        # the samples' cells, row and column apart (no (S, 2) temporaries)
        res, (ox, oy) = self.resolution, self.origin
        miss_r = np.floor((sensor_xy[1] + frac * delta[beam, 1] - oy) / res).astype(np.int64)
        miss_c = np.floor((sensor_xy[0] + frac * delta[beam, 0] - ox) / res).astype(np.int64)
        hit_rc = np.floor(self.to_cells(endpoints)).astype(np.int64)
        if hit_rc.size and (hit_rc.min() < 0 or (hit_rc >= (rows, cols)).any()):
            hit_rc = hit_rc[((hit_rc >= 0) & (hit_rc < (rows, cols))).all(axis=1)]
        # the samples of a ray run monotonically in row and column: its first and last
        # bound its cells (the sensor's is every ray's first)
        last = (np.cumsum(counts) - 1)[counts > 0]
        ends_rc = np.stack([miss_r[last], miss_c[last]], axis=1)
        if last.size:
            ends_rc = np.vstack([ends_rc, [(miss_r[0], miss_c[0])]])
        if ends_rc.size and (ends_rc.min() < 0 or (ends_rc >= (rows, cols)).any()):
            ok = (miss_r >= 0) & (miss_r < rows) & (miss_c >= 0) & (miss_c < cols)
            miss_r, miss_c = miss_r[ok], miss_c[ok]
            ends_rc = np.stack([miss_r, miss_c], axis=1)
        bound = np.concatenate([ends_rc, hit_rc])
        miss_flat = miss_r * cols + miss_c
        hit_flat = np.unique(hit_rc[:, 0] * cols + hit_rc[:, 1])
        flat = self.log_odds.reshape(-1)
        mark = self._mark
        mark[miss_flat] = True
        mark[hit_flat] = False
        miss_cells = np.flatnonzero(mark)
        mark[miss_cells] = False
        flat[miss_cells] = np.maximum(flat[miss_cells] + self.l_miss, self.l_min)
        flat[hit_flat] = np.minimum(flat[hit_flat] + self.l_hit, self.l_max)
        if miss_flat.size or hit_flat.size:
            r0, c0 = bound.min(axis=0)
            r1, c1 = bound.max(axis=0) + 1
            if self.touched is not None:
                r0, r1 = min(r0, self.touched[0]), max(r1, self.touched[1])
                c0, c1 = min(c0, self.touched[2]), max(c1, self.touched[3])
            self.touched = (int(r0), int(r1), int(c0), int(c1))

    def cropped(self, margin: int) -> LogOddsGrid:
        """A copy holding only the observed cells plus ``margin`` cells around them, for a
        submap that will not change any more (saves memory and its likelihood field's size)."""
        if self.touched is None:
            return self
        rows, cols = self.shape
        r0, r1, c0, c1 = self.touched
        r0, c0 = max(r0 - margin, 0), max(c0 - margin, 0)
        r1, c1 = min(r1 + margin, rows), min(c1 + margin, cols)
        out = object.__new__(LogOddsGrid)
        out.log_odds = self.log_odds[r0:r1, c0:c1].copy()
        out.origin = (
            self.origin[0] + c0 * self.resolution,
            self.origin[1] + r0 * self.resolution,
        )
        out.resolution = self.resolution
        out.l_hit, out.l_miss = self.l_hit, self.l_miss
        out.l_min, out.l_max = self.l_min, self.l_max
        out._mark = np.zeros(0, dtype=bool)
        t = self.touched
        out.touched = (t[0] - r0, t[1] - r0, t[2] - c0, t[3] - c0)
        return out

    def probabilities(self) -> np.ndarray:
        return 1.0 / (1.0 + np.exp(-self.log_odds))
