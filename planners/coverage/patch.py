"""Sweeping a patch of floor that no tour planned: furniture taken away after the plan was made.

The patch's cells are swept by parallel lanes along the longer side of its bounding box, as
the boustrophedon sweeps one cell of a decomposition (Choset, "Coverage of known spaces: the
boustrophedon cellular decomposition", Autonomous Robots 9, 2000): as few lines as cover the
patch's width at most ``spacing`` apart, spread evenly over it; on each line the runs of
robot-centre cells whose swath touches the patch, from where the patch's floor within the
brush's reach of the line begins to where it ends; the runs driven in turn, each line in the
opposite direction to the one before, joined by transits. What the lanes miss (a line the
robot centre cannot take by a wall, a ragged edge) is left to the tour's fill-in passes
(:func:`planners.coverage.fill_in.fill_in_tasks`), taken from where the lanes run and driven
after them in the same pass: a patch is one trip, however ragged.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from planners.coverage.fill_in import fill_in_tasks
from planners.coverage.metrics import swath
from planners.coverage.transit import Transit
from planners.grid import GridMap, dilate


def patch_lanes(
    grid: GridMap, floor: np.ndarray, reach: np.ndarray, half_width: float, spacing: float
) -> list[np.ndarray]:
    """The lane runs sweeping the cells ``floor`` from the robot-centre cells ``reach``, in
    driving order: each a (2, 2) world start and end on cell centres (the two may coincide)."""
    if not floor.any():
        return []
    along_x = _extent(floor, 1) >= _extent(floor, 0)
    # work on rows: lanes along x are rows, lanes along y are the transposed grid's rows
    f, ok = (floor, reach) if along_x else (floor.T, reach.T)
    touch = ok & dilate(f, half_width, grid.resolution)
    rows = np.flatnonzero(f.any(axis=1))
    lo, hi = rows[0] * grid.resolution, (rows[-1] + 1) * grid.resolution
    # the outer lines a cell inside the brush's reach of the patch's edges: a line falls on a
    # cell's centre, up to half a cell off
    edge = max(half_width - grid.resolution, 0.0)
    n = max(1, math.ceil((hi - lo - 2 * edge) / spacing - 1e-9) + 1)
    centres = lo + edge + (hi - lo - 2 * edge) * np.arange(n) / max(n - 1, 1)
    if n == 1 or hi - lo <= 2 * edge:
        centres = np.array([(lo + hi) / 2])
    lines = np.unique(np.clip(np.floor(centres / grid.resolution), 0, f.shape[0] - 1).astype(int))
    # a line's runs end where the patch's floor in its band (the rows its brush reaches) ends:
    # the brush's half width beyond that would sweep only floor the tour swept already
    band = int(half_width / grid.resolution)
    out = []
    for k, r in enumerate(lines):
        cols = np.flatnonzero(f[max(r - band, 0) : r + band + 1].any(axis=0))
        if not len(cols):
            continue
        line = touch[r].copy()
        line[: cols[0]] = False
        line[cols[-1] + 1 :] = False
        runs = _runs(line)
        if k % 2:
            runs = [(b, a) for a, b in runs[::-1]]
        for a, b in runs:
            rc = np.array([[r, a], [r, b]]) if along_x else np.array([[a, r], [b, r]])
            out.append(grid.cell_to_world(rc))
    return out


def patch_sweep(
    grid: GridMap,
    floor: np.ndarray,
    reach: np.ndarray,
    half_width: float,
    spacing: float,
    transit: Transit,
    target: float = 1.0,
) -> tuple[np.ndarray, float] | None:
    """(path, m² of ``floor`` its swath sweeps) of one pass over ``floor``, None when the brush
    reaches none of it: the lanes (:func:`patch_lanes`), then the fill-in passes for what they
    miss until ``target`` of it is swept (as the tour's ``coverage.fill_in_target``), each
    taken in turn from where the path ends, nearest end first, and joined by transits. A path
    of one point goes on to the neighbouring centre cell nearest the patch's middle, so that
    there is a path to drive."""
    lanes = patch_lanes(grid, floor, reach, half_width, spacing)
    covered = np.zeros_like(floor)
    anchors = np.zeros((0, 2))
    parts: list[np.ndarray] = []
    if lanes:
        parts.append(lanes[0])
        for a, b in itertools.pairwise(lanes):
            parts.append(np.vstack([transit.path(a[-1], b[0])[1:-1], b]))
        anchors = np.vstack(parts)
        covered = swath(grid, anchors, half_width)[0] & floor
    passes = [
        p
        for p, _ in fill_in_tasks(grid, covered, anchors, floor, reach, half_width, transit, target)
    ]
    if not parts and passes:
        parts.append(passes.pop(0))
    while passes:
        end = parts[-1][-1]
        gaps = [min(np.hypot(*(p[0] - end)), np.hypot(*(p[-1] - end))) for p in passes]
        p = passes.pop(int(np.argmin(gaps)))
        if np.hypot(*(p[-1] - end)) < np.hypot(*(p[0] - end)):
            p = p[::-1]
        parts.append(np.vstack([transit.path(end, p[0])[1:-1], p]))
    if not parts:
        return None
    path = np.vstack(parts)
    path = path[np.concatenate([[True], (np.diff(path, axis=0) != 0).any(axis=1)])]
    middle = grid.cell_to_world(np.argwhere(floor)).mean(axis=0)
    path = _drivable(grid, path, reach, middle)
    swept = swath(grid, path, half_width)[0] & floor
    return path, float(swept.sum()) * grid.resolution**2


def _extent(mask: np.ndarray, axis: int) -> int:
    """How many rows (``axis`` 0) or columns (1) the cells of ``mask`` span."""
    idx = np.flatnonzero(mask.any(axis=1 - axis))
    return int(idx[-1] - idx[0] + 1)


def _runs(line: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) index of each run of True in ``line``, in order."""
    edges = np.diff(np.concatenate([[0], line.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def _drivable(grid: GridMap, path: np.ndarray, reach: np.ndarray, middle: np.ndarray) -> np.ndarray:
    """``path`` as a path of two points at least: one point goes on to its neighbouring centre
    cell of ``reach`` nearest ``middle`` (or stays, when there is none)."""
    if len(path) > 1:
        return path
    r, c = grid.world_to_cell(path[0])
    steps = np.array([(r + dr, c + dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if dr or dc])
    steps = steps[grid.in_bounds(steps)]
    steps = steps[reach[steps[:, 0], steps[:, 1]]]
    if not len(steps):
        return np.vstack([path[:1], path[:1]])
    xy = grid.cell_to_world(steps)
    return np.vstack([path[:1], xy[np.argmin(np.hypot(*(xy - middle).T))]])
