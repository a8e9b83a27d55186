"""Lanes inside one boustrophedon cell, in the cell's rotated (row, col) coordinates.

Lanes run along rows at a row coordinate ``y`` (any real number: a robot centre may take it
where both rows next to it, ``floor(y)`` and ``ceil(y)``, are robot-centre cells). Where the
lanes lie is decided by :mod:`planners.coverage.lattice` (continuous lanes exactly the lane
spacing apart, one lattice per room); :func:`lane_rows` is the simple per-cell placement
(half-integer rows, the spacing rounded down to whole rows; first and last lanes half a row
inside the outermost rows).
"""

from __future__ import annotations

import math

import numpy as np

from planners.coverage.bcd import MonotoneCell


def lane_rows(cell: MonotoneCell, spacing_cells: float) -> np.ndarray:
    """Row coordinates (absolute; half-integers unless the cell is one row high) of its lanes:
    from half a row inside the first row, every ``spacing_cells`` (rounded down to whole rows,
    so swaths never leave a gap), and the last lane half a row inside the last row."""
    if cell.rows == 1:
        return np.array([float(cell.row0)])
    step = max(1, math.floor(spacing_cells + 1e-9))
    last = cell.rows - 2
    ys = [*list(range(0, last, step)), last]
    return cell.row0 + 0.5 + np.array(ys, dtype=float)


def lane_extent(cell: MonotoneCell, y: float) -> tuple[int, int]:
    """First and last column a robot centre may take on the lane at row coordinate ``y``."""
    a = math.floor(y) - cell.row0
    b = math.ceil(y) - cell.row0
    return int(max(cell.left[a], cell.left[b])), int(min(cell.right[a], cell.right[b]))


def lanes_of(cell: MonotoneCell, ys: np.ndarray) -> np.ndarray:
    """(n, 3) lanes at row coordinates ``ys`` spanning the cell's full extent."""
    return np.array([(float(y), *lane_extent(cell, float(y))) for y in ys], dtype=float)
