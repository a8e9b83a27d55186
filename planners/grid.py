"""Occupancy grids in world coordinates.

Conventions follow ROS ``nav_msgs/OccupancyGrid``: row 0 is the lowest y, cell ``(r, c)`` covers
``x ∈ [ox + c·res, ox + (c+1)·res)`` and ``y ∈ [oy + r·res, oy + (r+1)·res)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class GridMap:
    """A 2D occupancy grid: ``occupied`` and ``unknown`` are boolean arrays of shape (rows, cols)."""

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
        rc = np.asarray(rc, dtype=float)
        x = self.origin[0] + (rc[..., 1] + 0.5) * self.resolution
        y = self.origin[1] + (rc[..., 0] + 0.5) * self.resolution
        return np.stack([x, y], axis=-1)

    def in_bounds(self, rc: np.ndarray) -> np.ndarray:
        rc = np.asarray(rc)
        rows, cols = self.shape
        return (rc[..., 0] >= 0) & (rc[..., 0] < rows) & (rc[..., 1] >= 0) & (rc[..., 1] < cols)
