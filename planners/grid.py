"""Occupancy grids in world coordinates.

Conventions follow ROS ``nav_msgs/OccupancyGrid``: row 0 is the lowest y, cell ``(r, c)`` covers
``x ∈ [ox + c·res, ox + (c+1)·res)`` and ``y ∈ [oy + r·res, oy + (r+1)·res)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage


def cell_centres(rc: np.ndarray, resolution: float, origin: tuple[float, float]) -> np.ndarray:
    """(..., 2) (row, col) of a grid of ``resolution`` at ``origin`` → (..., 2) world
    coordinates of the cell centres."""
    rc = np.asarray(rc, dtype=float)
    x = origin[0] + (rc[..., 1] + 0.5) * resolution
    y = origin[1] + (rc[..., 0] + 0.5) * resolution
    return np.stack([x, y], axis=-1)


@dataclass(frozen=True, eq=False)
class GridMap:
    """A 2D occupancy grid: boolean ``occupied`` and ``unknown`` arrays of shape (rows, cols)."""

    occupied: np.ndarray
    unknown: np.ndarray
    resolution: float
    origin: tuple[float, float]

    @property
    def shape(self) -> tuple[int, int]:
        return self.occupied.shape  # type: ignore[return-value]

    @property
    def free(self) -> np.ndarray:
        return ~(self.occupied | self.unknown)

    def world_to_cell(self, xy: np.ndarray) -> np.ndarray:
        """(..., 2) world points → (..., 2) integer (row, col); may lie outside the grid."""
        xy = np.asarray(xy, dtype=float)
        col = np.floor((xy[..., 0] - self.origin[0]) / self.resolution).astype(np.int64)
        row = np.floor((xy[..., 1] - self.origin[1]) / self.resolution).astype(np.int64)
        return np.stack([row, col], axis=-1)

    def cell_to_world(self, rc: np.ndarray) -> np.ndarray:
        """(..., 2) (row, col) → (..., 2) world coordinates of the cell centres."""
        return cell_centres(rc, self.resolution, self.origin)

    def in_bounds(self, rc: np.ndarray) -> np.ndarray:
        rc = np.asarray(rc)
        rows, cols = self.shape
        return (rc[..., 0] >= 0) & (rc[..., 0] < rows) & (rc[..., 1] >= 0) & (rc[..., 1] < cols)


def clearance(grid: GridMap) -> np.ndarray:
    """Distance (m) from each cell centre to the nearest occupied or unknown cell's edge.

    Euclidean distance transform (scipy.ndimage) between cell centres, less half a cell so the
    value is the distance to the blocking cell's boundary; outside the grid counts as blocked.
    """
    blocked = np.pad(grid.occupied | grid.unknown, 1, constant_values=True)
    dist = ndimage.distance_transform_edt(~blocked)[1:-1, 1:-1]
    return np.maximum(dist - 0.5, 0.0) * grid.resolution


def inflate(grid: GridMap, radius: float) -> np.ndarray:
    """Cells where a disc robot of ``radius`` centred on the cell would touch a blocked cell."""
    return clearance(grid) < radius


def disc(radius: float, resolution: float) -> np.ndarray:
    """Boolean kernel of the cells whose centres lie strictly within ``radius`` of the centre."""
    n = int(np.ceil(radius / resolution))
    off = np.arange(-n, n + 1) * resolution
    return np.hypot(off[:, None], off[None, :]) < radius - 1e-9


def dilate(mask: np.ndarray, radius: float, resolution: float) -> np.ndarray:
    """``mask`` grown by a disc of ``radius`` (cell centres strictly inside count)."""
    kernel = disc(radius, resolution)
    if kernel.size <= 1:
        return mask.copy()
    return ndimage.binary_dilation(mask, structure=kernel)


def reachable(free_centres: np.ndarray, start_cells: np.ndarray) -> np.ndarray:
    """The cells of ``free_centres`` 4-connected to any of ``start_cells`` ((K, 2) row, col).

    4-connectivity is what an 8-connected path that never cuts a blocked corner can reach.
    """
    labels, _ = ndimage.label(free_centres)
    starts = np.atleast_2d(np.asarray(start_cells, dtype=np.int64))
    ids = labels[starts[:, 0], starts[:, 1]]
    ids = np.unique(ids[ids > 0])
    return np.isin(labels, ids)


def cleanable(grid: GridMap, reachable_centres: np.ndarray, swath_radius: float) -> np.ndarray:
    """Free cells a swath of ``swath_radius`` around some reachable robot-centre cell touches.

    The cleanable area is the reachable centre cells dilated by the swath footprint (cells whose
    centres lie strictly within ``swath_radius`` of a reachable centre), limited to free cells.
    """
    return dilate(reachable_centres, swath_radius, grid.resolution) & grid.free


def extend_labels(labels: np.ndarray, where: np.ndarray) -> np.ndarray:
    """Labels over ``where``: each unlabelled cell takes the label of its nearest labelled
    cell (Euclidean distance transform); cells outside ``where`` get 0."""
    if not (labels > 0).any():
        return np.zeros_like(labels)
    _, idx = ndimage.distance_transform_edt(labels == 0, return_indices=True)
    out = labels[idx[0], idx[1]]
    out[~where] = 0
    return out
