"""Targeted fill-in passes: short detours that sweep only the floor the planned paths missed.

After the sweeps, the cleanable cells no path covers are found with the footprint model of
:mod:`planners.coverage.metrics` (the capsules of the path's segments). Each missed cell is
within the swath of some robot-centre cell — that is what makes it cleanable — so the nearest
robot-centre cell to it is a point a detour can visit to clean it. Missed cells are taken
greedily (each chosen point clears every missed cell within its swath); points closer than a
swath width form one chain, visited in nearest-neighbour order — a contour pass along the wall
or furniture restricted to where it is needed. A chain is inserted into the path of the robot
passing closest to it, as an out-and-back detour from that path's nearest vertex (transits by
:class:`planners.coverage.transit.Transit`, so detours never cross blocked cells).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy import ndimage
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from planners.coverage.metrics import swath
from planners.coverage.transit import Transit
from planners.grid import GridMap, disc


def fill_points(
    clean: np.ndarray, covered: np.ndarray, reach: np.ndarray, half_width_cells: float
) -> tuple[np.ndarray, np.ndarray]:
    """(K, 2) robot-centre cells (row, col) whose swaths cover every missed cleanable cell, and
    how many missed cells each one newly covers."""
    missed = clean & ~covered
    if not missed.any() or not reach.any():
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0, dtype=np.int64)
    _, near = ndimage.distance_transform_edt(~reach, return_indices=True)
    kernel = disc(half_width_cells, 1.0)
    n = kernel.shape[0] // 2
    rows, cols = clean.shape
    out = []
    gain = []
    for r, c in np.argwhere(missed):
        if not missed[r, c]:
            continue
        q = (int(near[0, r, c]), int(near[1, r, c]))
        if math.hypot(q[0] - r, q[1] - c) >= half_width_cells - 1e-9:
            missed[r, c] = False
            continue
        out.append(q)
        r0, r1 = max(0, q[0] - n), min(rows, q[0] + n + 1)
        c0, c1 = max(0, q[1] - n), min(cols, q[1] + n + 1)
        k = kernel[r0 - q[0] + n : r1 - q[0] + n, c0 - q[1] + n : c1 - q[1] + n]
        gain.append(int((missed[r0:r1, c0:c1] & k).sum()))
        missed[r0:r1, c0:c1] &= ~k
    return np.array(out, dtype=np.int64).reshape(-1, 2), np.array(gain, dtype=np.int64)


def chains(points: np.ndarray, link: float) -> list[np.ndarray]:
    """Indices of ``points`` grouped by links shorter than ``link``, each group in
    nearest-neighbour order from its point farthest from the group's centroid."""
    if len(points) == 0:
        return []
    pairs = cKDTree(points).query_pairs(link, output_type="ndarray")
    n = len(points)
    graph = np.zeros((n, n), dtype=bool)
    graph[pairs[:, 0], pairs[:, 1]] = True
    _, comp = connected_components(graph, directed=False)
    out = []
    for c in np.unique(comp):
        ids = np.flatnonzero(comp == c)
        pts = points[ids].astype(float)
        k = int(np.argmax(np.hypot(*(pts - pts.mean(axis=0)).T)))
        order = [k]
        left = set(range(len(pts))) - {k}
        while left:
            last = pts[order[-1]]
            k = min(left, key=lambda j: float(np.hypot(*(pts[j] - last))))
            order.append(k)
            left.remove(k)
        out.append(ids[order])
    return out


def add_fill_in(
    grid: GridMap,
    paths: Sequence[np.ndarray],
    clean: np.ndarray,
    reach: np.ndarray,
    half_width: float,
    transit: Transit,
    target: float = 1.0,
) -> list[np.ndarray]:
    """``paths`` with out-and-back detours covering the cleanable cells they miss.

    Detours are taken in decreasing order of missed cells cleaned per metre driven until the
    covered share of ``clean`` reaches ``target`` (1.0: every detour).
    """
    covered = np.zeros(grid.shape, dtype=bool)
    for p in paths:
        covered |= swath(grid, p, half_width)[0]
    hw = half_width / grid.resolution
    pts, gain = fill_points(clean, covered, reach, hw)
    groups = chains(pts, 2 * hw)
    if not groups:
        return list(paths)
    verts = [np.asarray(p, dtype=float) for p in paths]
    options = []
    for ids in groups:
        chain = grid.cell_to_world(pts[ids])
        i, j, flip, dist = _nearest_vertex(verts, chain)
        along = float(np.hypot(*np.diff(chain, axis=0).T).sum())
        cost = 2 * (dist + along) + grid.resolution
        options.append((int(gain[ids].sum()) / cost, int(gain[ids].sum()), i, j, flip, chain))
    options.sort(key=lambda o: -o[0])
    missing = int((clean & ~covered).sum())
    allowed = (1.0 - target) * int(clean.sum())
    detours: list[list[tuple[int, np.ndarray]]] = [[] for _ in paths]
    for _, g, i, j, flip, chain in options:
        if missing <= allowed:
            break
        missing -= g
        detours[i].append((j, chain[::-1] if flip else chain))
    out = []
    for v, ds in zip(verts, detours, strict=True):
        if not ds:
            out.append(v)
            continue
        parts = []
        prev = 0
        for j, chain in sorted(ds, key=lambda t: t[0]):
            parts.append(v[prev : j + 1])
            parts.append(_detour(v[j], chain, transit)[1:])
            prev = j + 1
        parts.append(v[prev:])
        out.append(np.vstack(parts))
    return out


def _nearest_vertex(verts: list[np.ndarray], chain: np.ndarray) -> tuple[int, int, bool, float]:
    """(path, vertex, whether to drive the chain backwards, distance) of the path vertex
    nearest to either end of the chain."""
    best = (math.inf, 0, 0, False)
    for i, v in enumerate(verts):
        for flip, end in ((False, chain[0]), (True, chain[-1])):
            d = np.hypot(*(v - end).T)
            j = int(np.argmin(d))
            if d[j] < best[0]:
                best = (float(d[j]), i, j, flip)
    return best[1], best[2], best[3], best[0]


def _detour(v: np.ndarray, chain: np.ndarray, transit: Transit) -> np.ndarray:
    """From ``v`` through the chain's points and back to ``v``."""
    legs = [v[None, :]]
    cur = v
    for q in [*chain, v]:
        legs.append(transit.path(cur, q)[1:])
        cur = q
    return np.vstack(legs)
