"""Paths around the bodies of lost robots.

A robot whose agent dies leaves its body where it stopped: a disc no other robot may drive
through, which the floor plan does not show. :func:`with_bodies` marks the bodies on a grid,
and :func:`reroute` repairs a planned path on the grid of cells a robot centre may occupy
(``free``, computed from that grid): the stretches of the path whose centre line runs through
a blocked cell are dropped, and the runs left are joined by transits planned around what
blocks them (A*, :class:`planners.coverage.transit.Transit`); where no transit joins two runs,
the path falls apart into separate paths, each of which some robot may still reach from
elsewhere. This is how a coverage planner treats an obstacle that appears on a known map
(the boustrophedon cells are cut by it, Choset 2000), done on the tour already planned, so
the floor swept so far and the tasks sold stay as they are.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planners.coverage.transit import Transit
from planners.grid import GridMap
from planners.polyline import path_length

# samples per cell along the path when its cells are looked up
_SAMPLES_PER_CELL = 3


def with_bodies(grid: GridMap, centres: np.ndarray, radius: float) -> GridMap:
    """``grid`` with every cell whose centre lies within ``radius`` of one of ``centres``
    ((K, 2) world metres) marked occupied."""
    centres = np.asarray(centres, dtype=float).reshape(-1, 2)
    occupied = grid.occupied.copy()
    if len(centres):
        rows, cols = grid.shape
        xy = grid.cell_to_world(np.stack(np.mgrid[0:rows, 0:cols], axis=-1))
        for c in centres:
            occupied |= np.hypot(xy[..., 0] - c[0], xy[..., 1] - c[1]) <= radius
    return GridMap(occupied, grid.unknown, grid.resolution, grid.origin)


@dataclass(frozen=True)
class Rerouted:
    """A path repaired around blocked cells.

    ``paths``: the drivable parts in their order along the old path, each (N, 2) with N ≥ 2:
    runs of the old path joined by transits around what lay between them (one path when every
    gap could be bridged, none when nothing of the old path is drivable). ``dropped``: the
    stretches of the old path that ran through blocked cells, each (N, 2), in order.
    ``changed``: whether anything was dropped."""

    paths: tuple[np.ndarray, ...]
    dropped: tuple[np.ndarray, ...]

    @property
    def changed(self) -> bool:
        return bool(self.dropped)


def reroute(
    path: np.ndarray,
    free: np.ndarray,
    grid: GridMap,
    min_run: float,
    max_detour: float = np.inf,
) -> Rerouted:
    """``path`` (N, 2) repaired on ``free`` (the grid's cells a robot centre may occupy): see
    the module docstring. Runs shorter than ``min_run`` metres are dropped with the stretches
    around them; a transit joins two runs only when it is at most ``max_detour`` metres longer
    than the straight line between them."""
    path = np.asarray(path, dtype=float)
    runs, dropped = _split(path, free, grid, min_run)
    if not dropped:
        return Rerouted((path,), ())
    transit = Transit(grid, free)
    paths: list[np.ndarray] = []
    for run in runs:
        if paths:
            try:
                bridge = transit.path(paths[-1][-1], run[0])
            except ValueError:
                paths.append(run)
                continue
            gap = float(np.hypot(*(run[0] - paths[-1][-1])))
            if path_length(bridge) > gap + max_detour:
                paths.append(run)
                continue
            paths[-1] = np.vstack([paths[-1], bridge[1:-1], run])
        else:
            paths.append(run)
    return Rerouted(tuple(paths), tuple(dropped))


def _split(
    path: np.ndarray, free: np.ndarray, grid: GridMap, min_run: float
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The runs of ``path`` over free cells (the path's own vertices, cut where it enters and
    leaves blocked cells) and the stretches between them."""
    seg = np.diff(path, axis=0)
    n = np.maximum(1, np.ceil(np.hypot(*seg.T) * _SAMPLES_PER_CELL / grid.resolution)).astype(int)
    i = np.repeat(np.arange(len(seg)), n)
    frac = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)) / n[i]
    pts = np.vstack([path[i] + frac[:, None] * seg[i], path[-1:]])
    vertex = np.concatenate([frac == 0, [True]])
    rc = grid.world_to_cell(pts)
    inside = grid.in_bounds(rc)
    ok = np.zeros(len(pts), dtype=bool)
    ok[inside] = free[rc[inside, 0], rc[inside, 1]]
    runs: list[np.ndarray] = []
    dropped: list[np.ndarray] = []
    edges = np.flatnonzero(np.diff(np.concatenate([[False], ok, [False]]).astype(np.int8)))
    starts, ends = edges[::2], edges[1::2] - 1
    last_end = -1
    for a, b in zip(starts, ends, strict=True):
        run = _points(pts, vertex, a, b)
        if len(run) < 2 or path_length(run) < min_run:
            continue
        if a > last_end + 1:
            dropped.append(_points(pts, vertex, max(last_end, 0), a))
        runs.append(run)
        last_end = b
    if last_end < len(pts) - 1:
        dropped.append(_points(pts, vertex, max(last_end, 0), len(pts) - 1))
    return runs, dropped


def _points(pts: np.ndarray, vertex: np.ndarray, a: int, b: int) -> np.ndarray:
    """The samples ``a`` and ``b`` with the path's vertices between them."""
    keep = np.zeros(len(pts), dtype=bool)
    keep[a : b + 1] = vertex[a : b + 1]
    keep[a] = keep[b] = True
    out = pts[keep]
    moved = np.concatenate([[True], np.hypot(*np.diff(out, axis=0).T) > 1e-9])
    return out[moved]
