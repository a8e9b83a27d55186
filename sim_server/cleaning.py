"""Ground-truth cleaning: which floor cells each robot's brush has swept, and how often.

The floor is a grid of ``cell_size`` cells. A robot's brush is a disc of diameter
``cleaning_width`` centred on the robot, so moving straight it sweeps a band of that width.
A cell's visit count goes up by one each time it *enters* a robot's brush (it was not under that
brush at the previous update), so a robot standing still does not inflate the counts and a pass
over a cell counts once however slowly it is made.

The reference is the **cleanable area**: cells whose centre a robot centre can reach from the
start poses (clearance ≥ robot radius from occupied or unknown cells, connected to a start),
dilated by the brush. Coverage = swept cleanable cells / cleanable cells; repetition =
(visits summed over swept cells) / (swept cells) − 1.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from planners.grid import GridMap


def disc_offsets(radius: float, resolution: float) -> np.ndarray:
    """(K, 2) integer (row, col) offsets of the cells whose centres lie within ``radius``."""
    k = int(np.ceil(radius / resolution))
    r, c = np.mgrid[-k : k + 1, -k : k + 1]
    inside = np.hypot(r, c) * resolution <= radius + 1e-9
    return np.stack([r[inside], c[inside]], axis=1)


def reachable_centres(grid: GridMap, starts_xy: np.ndarray, robot_radius: float) -> np.ndarray:
    """Cells a robot centre can occupy and reach from any of the starts (boolean grid)."""
    blocked = grid.occupied | grid.unknown
    # Clearance of a cell centre to the nearest blocked cell's edge.
    clearance = ndimage.distance_transform_edt(~blocked) * grid.resolution - grid.resolution / 2
    ok = clearance >= robot_radius
    labels, _ = ndimage.label(ok)
    rc = grid.world_to_cell(np.atleast_2d(starts_xy))
    rc = rc[grid.in_bounds(rc)]
    ids = {int(labels[r, c]) for r, c in rc} - {0}
    return np.isin(labels, sorted(ids)) if ids else np.zeros_like(ok)


def cleanable_mask(
    grid: GridMap, starts_xy: np.ndarray, robot_radius: float, cleaning_width: float
) -> np.ndarray:
    """Reachable robot-centre cells dilated by the brush disc, limited to free cells."""
    centres = reachable_centres(grid, starts_xy, robot_radius)
    brush = disc_offsets(cleaning_width / 2, grid.resolution)
    k = int(np.abs(brush).max()) if len(brush) else 0
    fp = np.zeros((2 * k + 1, 2 * k + 1), dtype=bool)
    fp[brush[:, 0] + k, brush[:, 1] + k] = True
    return ndimage.binary_dilation(centres, structure=fp) & grid.free


class CleaningGrid:
    """Visit counts of every floor cell, updated from the robots' true positions."""

    def __init__(self, grid: GridMap, cleanable: np.ndarray, cleaning_width: float) -> None:
        self.grid = grid
        self.cleanable = cleanable
        self.visits = np.zeros(grid.shape, dtype=np.uint16)
        self._brush = disc_offsets(cleaning_width / 2, grid.resolution)
        self._centre: dict[str, tuple[int, int]] = {}
        self._last: dict[str, np.ndarray] = {}

    def update(self, robot: str, x: float, y: float) -> None:
        """Sweep ``robot``'s brush at (x, y); cheap when it has not left its cell."""
        g = self.grid
        centre = (int((y - g.origin[1]) // g.resolution), int((x - g.origin[0]) // g.resolution))
        if self._centre.get(robot) == centre:
            return
        self._centre[robot] = centre
        rows, cols = g.shape
        rc = self._brush + np.array(centre)
        ok = (rc[:, 0] >= 0) & (rc[:, 0] < rows) & (rc[:, 1] >= 0) & (rc[:, 1] < cols)
        flat = rc[ok, 0] * cols + rc[ok, 1]
        prev = self._last.get(robot)
        new = flat if prev is None else flat[~np.isin(flat, prev, assume_unique=True)]
        np.add.at(self.visits.reshape(-1), new, 1)
        self._last[robot] = flat

    def forget(self, robot: str) -> None:
        """A robot left; its next appearance starts a fresh pass."""
        self._last.pop(robot, None)
        self._centre.pop(robot, None)

    @property
    def cleanable_m2(self) -> float:
        return float(self.cleanable.sum()) * self.grid.resolution**2

    def coverage(self) -> float:
        total = int(self.cleanable.sum())
        if total == 0:
            return 0.0
        return float(np.count_nonzero(self.visits[self.cleanable])) / total

    def repetition(self) -> float:
        v = self.visits[self.cleanable]
        swept = np.count_nonzero(v)
        return float(v.sum(dtype=np.int64)) / swept - 1.0 if swept else 0.0
