"""Robots' occupancy maps carried into one frame and fused into one grid.

Each robot's SLAM map is a log-odds raster in its own map frame; the agents publish it as ROS
OccupancyGrid values (int8: −1 never observed, 0..100 occupancy percent), which
:meth:`LogOddsMap.from_ros` turns back into log-odds. A rigid transform (SE(2),
:class:`Transform2D`) carries a map frame into the common frame. Each map is resampled onto
the common grid with ``scipy.ndimage.affine_transform`` (linear for the log-odds, nearest for
the mask of observed cells, so a wall's edge blends but the unknown stays unknown) and the maps
are fused by adding their log-odds, the Bayesian update for independent evidence (Thrun et al.,
Probabilistic Robotics §9.2), clamped to the SLAM map's bounds. Fusing maps once their relative
transform is known is the second half of Birk and Carpin, "Merging occupancy grid maps from
multiple robots" (Proc. IEEE 2006); :mod:`planners.map_match` finds the transforms.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from planners.grid import GridMap, cell_centres


@dataclass(frozen=True)
class Transform2D:
    """The rigid transform p ↦ R(theta)·p + (x, y): a map frame's pose in the common frame."""

    x: float
    y: float
    theta: float

    @staticmethod
    def identity() -> Transform2D:
        return Transform2D(0.0, 0.0, 0.0)

    def apply(self, xy: np.ndarray) -> np.ndarray:
        """(..., 2) points of the map frame → (..., 2) points of the common frame."""
        xy = np.asarray(xy, dtype=float)
        c, s = math.cos(self.theta), math.sin(self.theta)
        x = c * xy[..., 0] - s * xy[..., 1] + self.x
        y = s * xy[..., 0] + c * xy[..., 1] + self.y
        return np.stack([x, y], axis=-1)

    def compose(self, other: Transform2D) -> Transform2D:
        """``self ∘ other``: ``other`` first, then ``self``."""
        x, y = self.apply(np.array([other.x, other.y]))
        return Transform2D(float(x), float(y), wrap_angle(self.theta + other.theta))

    def inverse(self) -> Transform2D:
        c, s = math.cos(self.theta), math.sin(self.theta)
        return Transform2D(-c * self.x - s * self.y, s * self.x - c * self.y, -self.theta)


def wrap_angle(theta: float) -> float:
    """``theta`` in [−π, π)."""
    return (theta + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(frozen=True, eq=False)
class LogOddsMap:
    """Log-odds (rows, cols) with ``planners.grid.GridMap``'s cell conventions (row 0 = lowest y,
    cell (r, c) starts at ``origin + (c, r)·resolution``). Zero log-odds means never observed."""

    log_odds: np.ndarray
    resolution: float
    origin: tuple[float, float]

    @property
    def shape(self) -> tuple[int, int]:
        return self.log_odds.shape  # type: ignore[return-value]

    @staticmethod
    def from_ros(
        cells: np.ndarray,
        resolution: float,
        origin: tuple[float, float],
        limits: tuple[float, float],
    ) -> LogOddsMap:
        """From ROS OccupancyGrid values: −1 (never observed) → 0, else log(p / (1 − p)) with
        p = value / 100, clamped to ``limits`` (the SLAM map's log-odds bounds, so 0 and 100
        stay finite)."""
        cells = np.asarray(cells)
        p = np.clip(cells.astype(np.float64) / 100.0, 1e-6, 1.0 - 1e-6)
        lo = np.clip(np.log(p / (1.0 - p)), limits[0], limits[1])
        lo[cells < 0] = 0.0
        return LogOddsMap(lo.astype(np.float32), float(resolution), origin)

    def probabilities(self) -> np.ndarray:
        return 1.0 / (1.0 + np.exp(-self.log_odds))

    def cell_to_world(self, rc: np.ndarray) -> np.ndarray:
        """(..., 2) (row, col) → (..., 2) world coordinates of the cell centres."""
        return cell_centres(rc, self.resolution, self.origin)

    def to_gridmap(self, occupied_threshold: float, free_threshold: float) -> GridMap:
        """Occupied where p ≥ occupied_threshold, unknown where p is strictly between the two."""
        p = self.probabilities()
        occupied = p >= occupied_threshold
        return GridMap(occupied, ~occupied & (p > free_threshold), self.resolution, self.origin)


def affine_onto(
    values: np.ndarray,
    resolution: float,
    origin: tuple[float, float],
    transform: Transform2D,
    target: GridMap | LogOddsMap,
    order: int,
) -> np.ndarray:
    """``values`` of a grid (``resolution``, ``origin``) whose frame ``transform`` carries into
    the common frame, sampled at the cell centres of ``target``'s grid (0 outside ``values``).

    ``scipy.ndimage.affine_transform`` maps each target cell (r, c) to the fractional source
    cell (r', c') = A·(r, c) + b, with A = (target resolution / source resolution)·R(−theta)
    in (row, col) order: cell centres sit at integer indices in both grids.
    """
    inv = transform.inverse()
    scale = target.resolution / resolution
    c, s = math.cos(inv.theta), math.sin(inv.theta)
    # the target's cell (0, 0) centre, in the source frame, as a fractional source cell
    x0, y0 = inv.apply(np.array(target.origin) + 0.5 * target.resolution)
    col0 = (x0 - origin[0]) / resolution - 0.5
    row0 = (y0 - origin[1]) / resolution - 0.5
    matrix = scale * np.array([[c, s], [-s, c]])
    return ndimage.affine_transform(
        values,
        matrix,
        offset=(row0, col0),
        output_shape=target.shape,
        order=order,
        mode="grid-constant",
        cval=0.0,
        prefilter=False,
    )


def common_grid(
    maps: Sequence[LogOddsMap], transforms: Sequence[Transform2D], resolution: float
) -> LogOddsMap:
    """An all-unknown grid of ``resolution`` holding every map's transformed extent, its origin
    on a multiple of ``resolution`` so merges of the same maps share cells."""
    corners = []
    for m, t in zip(maps, transforms, strict=True):
        rows, cols = m.shape
        ox, oy = m.origin
        box = np.array([[0, 0], [cols, 0], [0, rows], [cols, rows]]) * m.resolution + (ox, oy)
        corners.append(t.apply(box))
    pts = np.concatenate(corners)
    # a rounding error must not add a row of cells: corners within 1e-6 cells of a cell
    # boundary are on it
    lo = np.floor(pts.min(axis=0) / resolution + 1e-6) * resolution
    hi = np.ceil(pts.max(axis=0) / resolution - 1e-6) * resolution
    cols, rows = np.rint((hi - lo) / resolution).astype(int)
    return LogOddsMap(
        np.zeros((rows, cols), dtype=np.float32), resolution, (float(lo[0]), float(lo[1]))
    )


def resample(m: LogOddsMap, transform: Transform2D, target: LogOddsMap) -> np.ndarray:
    """``m``'s log-odds on ``target``'s grid: linear where the nearest source cell was observed,
    0 (never observed) elsewhere."""
    args = (m.resolution, m.origin, transform, target)
    observed = affine_onto((m.log_odds != 0).astype(np.uint8), *args, order=0) > 0
    lo = affine_onto(m.log_odds.astype(np.float32), *args, order=1)
    return np.where(observed, lo, np.float32(0.0))


def merge_maps(
    maps: Sequence[LogOddsMap],
    transforms: Sequence[Transform2D],
    limits: tuple[float, float],
    resolution: float | None = None,
) -> LogOddsMap:
    """Fuse ``maps`` (each carried into the common frame by its transform) into one grid of
    ``resolution`` (default: the first map's): the sum of their resampled log-odds, clamped to
    ``limits``."""
    if not maps:
        raise ValueError("no maps to merge")
    if len(maps) != len(transforms):
        raise ValueError(f"{len(maps)} maps but {len(transforms)} transforms")
    target = common_grid(maps, transforms, resolution or maps[0].resolution)
    total = np.zeros(target.shape, dtype=np.float32)
    for m, t in zip(maps, transforms, strict=True):
        total += resample(m, t, target)
    np.clip(total, limits[0], limits[1], out=total)
    return LogOddsMap(total, target.resolution, target.origin)
