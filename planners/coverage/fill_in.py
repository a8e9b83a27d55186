"""Targeted fill-in passes: short detours that sweep only the floor the planned paths missed.

After the sweeps, the cleanable cells no path covers are found with the footprint model of
:mod:`planners.coverage.metrics` (the capsules of the path's segments). Each missed cell is
within the swath of some robot-centre cell — that is what makes it cleanable — so the nearest
robot-centre cell to it is a point a detour can visit to clean it. Missed cells are taken
greedily (each chosen point clears every missed cell within its swath); points closer than
``CHAIN_LINK`` half swath widths form one chain, visited in nearest-neighbour order — a contour
pass along the wall or furniture restricted to where it is needed. Each chain becomes a task of
its own: the tour (:mod:`planners.coverage.tour`) enters and leaves it wherever that costs
least, so it is a leg of the tour rather than an out-and-back stub from the nearest path vertex.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
from scipy import ndimage
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from planners.coverage.transit import Transit
from planners.grid import GridMap, disc
from planners.polyline import path_length

# points closer than this many half swath widths join one chain; wider links (a full swath)
# merged points whose own best insertions into the tour lie apart, and measured longer paths
CHAIN_LINK = 1.25


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
        out.append(ids[_untangle(pts, np.array(order))])
    return out


def _untangle(pts: np.ndarray, order: np.ndarray) -> np.ndarray:
    """``order`` improved by 2-opt on the open path (Croes 1958; either end may move): a
    nearest-neighbour chain that ran off to one end and has to come back the same way is
    partly reversed instead."""
    n = len(pts)
    d = np.zeros((n + 1, n + 1))
    d[:n, :n] = np.hypot(*(pts[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
    # a free node at both ends, at no distance from anything, makes the open path a cycle
    seq = np.concatenate([[n], order, [n]])
    improved = True
    while improved:
        improved = False
        for i in range(len(seq) - 3):
            a, b = seq[i], seq[i + 1]
            c, e = seq[i + 2 : -1], seq[i + 3 :]
            gain = d[a, b] + d[c, e] - d[a, c] - d[b, e]
            k = int(np.argmax(gain))
            if gain[k] > 1e-9:
                seq = np.concatenate([seq[: i + 1], seq[i + 1 : i + 3 + k][::-1], seq[i + 3 + k :]])
                improved = True
    return seq[1:-1]


def fill_in_tasks(
    grid: GridMap,
    covered: np.ndarray,
    anchors: np.ndarray,
    clean: np.ndarray,
    reach: np.ndarray,
    half_width: float,
    transit: Transit,
    target: float = 1.0,
) -> list[tuple[np.ndarray, float]]:
    """(path, area m²) of the passes cleaning what ``covered`` misses, until ``target``.

    Each chain of :func:`fill_points` becomes one pass (its points joined by transits, so it
    never crosses blocked cells). Passes are taken in decreasing order of missed cells cleaned
    per metre — the chain's length plus twice its distance from the nearest of ``anchors``
    (points along the driven paths, so a chain beside a lane's middle counts as near), the
    detour it costs — until the covered share of ``clean`` reaches ``target`` (1.0: every
    pass); once the next pass alone would reach it, the cheapest pass that does is taken
    instead (the usual repair of greedy covering: the last pass need not be the densest, only
    enough). The tour then places them like any other task.
    """
    hw = half_width / grid.resolution
    pts, gain = fill_points(clean, covered, reach, hw)
    groups = chains(pts, CHAIN_LINK * hw)
    if not groups:
        return []
    tree = cKDTree(anchors) if len(anchors) else None
    options = []
    for ids in groups:
        chain = grid.cell_to_world(pts[ids])
        along = path_length(chain)
        dist = float(tree.query(chain[[0, -1]])[0].min()) if tree is not None else 0.0
        g = int(gain[ids].sum())
        cost = 2 * dist + along + grid.resolution
        options.append((g / cost, cost, g, chain))
    options.sort(key=lambda o: -o[0])
    missing = int((clean & ~covered).sum())
    allowed = (1.0 - target) * int(clean.sum())
    out = []
    while options and missing > allowed:
        k = 0
        if options[0][2] >= missing - allowed:
            # the last pass needed: the cheapest one that reaches the target by itself
            k = min(
                (i for i, o in enumerate(options) if o[2] >= missing - allowed),
                key=lambda i: options[i][1],
            )
        _, _, g, chain = options.pop(k)
        missing -= g
        legs = [chain[:1]] + [transit.path(a, b)[1:] for a, b in itertools.pairwise(chain)]
        out.append((np.vstack(legs), g * grid.resolution**2))
    return out
