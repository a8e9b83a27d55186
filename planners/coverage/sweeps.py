"""Sweep paths inside one boustrophedon cell, in the cell's rotated (row, col) coordinates.

Lanes run along rows at a row coordinate ``y`` (any real number: a robot centre may take it
where both rows next to it, ``floor(y)`` and ``ceil(y)``, are robot-centre cells). Where the
lanes lie is decided by :mod:`planners.coverage.lattice` (continuous lanes exactly the lane
spacing apart, one lattice per room); :func:`lane_rows` is the simple per-cell placement
(half-integer rows, the spacing rounded down to whole rows; first and last lanes half a row
inside the outermost rows) used by the spiral's core. Consecutive lanes are joined along the
cell's side (its outermost cells row by row), so the swath also reaches into the corners a
straight lane misses.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

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


def boustrophedon(cell: MonotoneCell, lanes: np.ndarray, left_first: bool) -> np.ndarray:
    """(P, 2) (row, col) polyline over ``lanes`` ((n, 3): row coordinate, first and last
    column) in the given order, zig-zagging.

    The first lane runs left → right when ``left_first``; each turn follows the cell side.
    """
    pts: list[tuple[float, float]] = []
    to_right = left_first
    for k, (y, lo, hi) in enumerate(np.asarray(lanes, dtype=float).reshape(-1, 3)):
        a, b = (lo, hi) if to_right else (hi, lo)
        if k > 0:
            pts.extend(_side(cell, pts[-1], (float(y), float(a)), right=not to_right))
        pts.append((float(y), float(a)))
        pts.append((float(y), float(b)))
        to_right = not to_right
    return np.array(pts, dtype=float)


def lanes_of(cell: MonotoneCell, ys: np.ndarray) -> np.ndarray:
    """(n, 3) lanes at row coordinates ``ys`` spanning the cell's full extent."""
    return np.array([(float(y), *lane_extent(cell, float(y))) for y in ys], dtype=float)


def _side(
    cell: MonotoneCell, p: tuple[float, float], q: tuple[float, float], right: bool
) -> list[tuple[float, float]]:
    """Staircase points from ``p`` to ``q`` (exclusive) along the cell's right or left side."""
    y0, y1 = p[0], q[0]
    step = 1 if y1 > y0 else -1
    first = math.ceil(y0) if step > 0 else math.floor(y0)
    last = math.floor(y1) if step > 0 else math.ceil(y1)
    rows = np.arange(first, last + step, step)
    rows = rows[(rows >= cell.row0) & (rows < cell.row0 + cell.rows)]
    side = cell.right if right else cell.left
    targets = [(float(r), float(side[r - cell.row0])) for r in rows] + [q]
    out: list[tuple[float, float]] = []
    cur = p
    for t in targets:
        outward = t[1] > cur[1] if right else t[1] < cur[1]
        corner = (t[0], cur[1]) if outward else (cur[0], t[1])
        out.append(corner)
        if t is not q:
            out.append(t)
        cur = t
    return out


def eroded_sides(cell: MonotoneCell, inset: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows, left, right) of the cell shrunk by ``inset`` cells on every side (may be empty).

    A square erosion of a row-monotone region: each row takes the tightest interval of the rows
    within ``inset`` of it, narrowed by ``inset``.
    """
    size = 2 * inset + 1
    left = ndimage.maximum_filter1d(cell.left, size, mode="nearest") + inset
    right = ndimage.minimum_filter1d(cell.right, size, mode="nearest") - inset
    k = np.arange(cell.rows)
    ok = (k >= inset) & (k < cell.rows - inset) & (left <= right)
    return cell.row0 + k[ok], left[ok], right[ok]
