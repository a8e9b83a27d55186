"""Ground-truth cleaning: which floor cells each robot's brush has swept, and how often.

The floor is a grid of ``cell_size`` cells. A robot's brush is a disc of diameter
``cleaning_width`` centred on the robot, so moving straight it sweeps a band of that width; a
cell is under the brush when its centre lies strictly inside the disc, the footprint rule of
``planners.grid.disc``.
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

from planners.grid import GridMap, cleanable, inflate, reachable


def cleanable_mask(
    grid: GridMap, starts_xy: np.ndarray, robot_radius: float, cleaning_width: float
) -> np.ndarray:
    """The reference area, as the planners define it (``planners.grid``): robot-centre cells
    with clearance ≥ ``robot_radius`` connected to a start, grown by the brush disc."""
    free_centres = ~inflate(grid, robot_radius)
    cells = grid.world_to_cell(np.atleast_2d(starts_xy))
    cells = cells[grid.in_bounds(cells)]
    cells = cells[free_centres[cells[:, 0], cells[:, 1]]]
    if len(cells) == 0:
        return np.zeros(grid.shape, dtype=bool)
    return cleanable(grid, reachable(free_centres, cells), cleaning_width / 2)


class CleaningGrid:
    """Visit counts of every floor cell, updated from the robots' true positions."""

    def __init__(self, grid: GridMap, cleanable: np.ndarray, cleaning_width: float) -> None:
        self.grid = grid
        self.cleanable = cleanable
        self.visits = np.zeros(grid.shape, dtype=np.uint16)
        self.radius = cleaning_width / 2
        k = int(np.ceil(self.radius / grid.resolution)) + 1
        self._window = np.stack(np.mgrid[-k : k + 1, -k : k + 1], axis=-1).reshape(-1, 2)
        self._pos: dict[str, tuple[float, float]] = {}
        self._last: dict[str, np.ndarray] = {}

    def footprint(self, x: float, y: float) -> np.ndarray:
        """Flat indices of the cells whose centres lie within the brush radius of (x, y)."""
        g = self.grid
        centre = g.world_to_cell(np.array([x, y]))
        rc = self._window + centre
        xy = g.cell_to_world(rc)
        inside = np.hypot(xy[:, 0] - x, xy[:, 1] - y) < self.radius - 1e-9
        rows, cols = g.shape
        rc = rc[inside & (rc[:, 0] >= 0) & (rc[:, 0] < rows) & (rc[:, 1] >= 0) & (rc[:, 1] < cols)]
        return rc[:, 0] * cols + rc[:, 1]

    def update(self, robot: str, x: float, y: float) -> None:
        """Sweep ``robot``'s brush at (x, y); a no-op until it has moved a quarter cell."""
        last = self._pos.get(robot)
        if last is not None and abs(x - last[0]) + abs(y - last[1]) < self.grid.resolution / 4:
            return
        self._pos[robot] = (x, y)
        flat = self.footprint(x, y)
        prev = self._last.get(robot)
        new = flat if prev is None else flat[~np.isin(flat, prev, assume_unique=True)]
        np.add.at(self.visits.reshape(-1), new, 1)
        self._last[robot] = flat

    def forget(self, robot: str) -> None:
        """A robot left; its next appearance starts a fresh pass."""
        self._last.pop(robot, None)
        self._pos.pop(robot, None)

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
