"""Submap trimming for a robot that maps the same floor again and again.

In the spirit of Cartographer's pure-localization trimmer (Hess et al. 2016; Cartographer's
``PureLocalizationTrimmer``), which keeps a localizing robot's memory bounded by dropping its
old submaps and their nodes: here a finished submap is dropped when older submaps still kept
have already observed all but a small share of the cells it observed (the robot re-mapped known
floor: they hold its walls), with its grid and its likelihood field; its log-odds are first
folded into those older submaps' grids, so the map composed from them keeps the evidence. Unlike
Cartographer's trimmer it leaves the submap's pose and nodes in the pose graph: dropping them
cost accuracy, and they weigh a few dozen bytes each. The kept submaps are those that added
floor, so their number is bounded by the floor's size, not by how long the robot drives (the
pose graph still grows with the drive, by a node per scan that moved enough).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agents.slam.geometry import inverse, transform_points
from agents.slam.submaps import Submap


def observed_points(s: Submap, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) map-frame centres of the submap's observed cells (log-odds not 0) at ``pose``,
    and their (N,) log-odds."""
    if s.grid.touched is None:
        return np.zeros((0, 2)), np.zeros(0)
    r0, r1, c0, c1 = s.grid.touched
    block = s.grid.log_odds[r0:r1, c0:c1]
    rows, cols = np.nonzero(block)
    res = s.grid.resolution
    local = np.stack(
        [
            s.grid.origin[0] + (cols + c0 + 0.5) * res,
            s.grid.origin[1] + (rows + r0 + 0.5) * res,
        ],
        axis=1,
    )
    return transform_points(pose, local), block[rows, cols]


@dataclass(frozen=True, eq=False)
class Cover:
    """Where the cells a submap observed lie in the older submaps: ``share``, the share of its
    wall cells an older submap holds as wall too, and per older submap the (row, col) cells
    there (``cells``, (N, 2)) with the log-odds the newer submap holds for them (``values``)."""

    share: float
    parts: list[tuple[Submap, np.ndarray, np.ndarray]]


def cover(s: Submap, older: list[Submap], poses: np.ndarray, occupied: float) -> Cover:
    """How much of what ``s`` observed the ``older`` submaps hold (each at its pose-graph pose,
    ``poses[graph_id]``): the share of its wall cells (log-odds at least ``occupied``) that
    one of them holds as wall too (1 when ``s`` saw no wall; walls are what scans are matched
    on, and a wall seen from afar through a doorway is seldom firm enough to count), and for
    every cell it observed the first of them that observed the cell too, else one whose grid
    reaches it (a cropped grid keeps a margin around what it observed)."""
    points, values = observed_points(s, poses[s.graph_id])
    walls = values >= occupied
    if points.shape[0] == 0:
        return Cover(1.0, [])
    lo, hi = points.min(axis=0), points.max(axis=0)
    seen = np.zeros(points.shape[0], dtype=bool)
    held = np.zeros(points.shape[0], dtype=bool)
    parts = []
    for k in older:
        if k.grid.touched is None or not _overlaps(k, poses[k.graph_id], lo, hi):
            continue
        cells = np.floor(
            k.grid.to_cells(transform_points(inverse(poses[k.graph_id]), points))
        ).astype(np.int64)
        r0, r1, c0, c1 = k.grid.touched
        inside = (cells[:, 0] >= r0) & (cells[:, 0] < r1) & (cells[:, 1] >= c0) & (cells[:, 1] < c1)
        theirs = np.zeros(points.shape[0], dtype=np.float32)
        theirs[inside] = k.grid.log_odds[cells[inside, 0], cells[inside, 1]]
        held |= walls & (theirs >= occupied)
        new = (theirs != 0) & ~seen
        if new.any():
            seen |= new
            parts.append((k, cells[new], values[new]))
    share = float(held.sum() / walls.sum()) if walls.any() else 1.0
    for k in older:
        todo = np.flatnonzero(~seen)
        if todo.size == 0:
            break
        if k.grid.touched is None:
            continue
        local = transform_points(inverse(poses[k.graph_id]), points[todo])
        cells = np.floor(k.grid.to_cells(local)).astype(np.int64)
        rows, cols = k.grid.shape
        inside = (
            (cells[:, 0] >= 0) & (cells[:, 0] < rows) & (cells[:, 1] >= 0) & (cells[:, 1] < cols)
        )
        if inside.any():
            seen[todo[inside]] = True
            parts.append((k, cells[inside], values[todo[inside]]))
    return Cover(share, parts)


def fold(c: Cover) -> list[Submap]:
    """Add the dropped submap's log-odds into the older submaps' cells that cover them (within
    each grid's clamps), so the map composed from the kept submaps keeps the evidence of the
    re-mapped floor: each scan still counts twice over them, as when every submap was kept.
    Their likelihood fields, which loop closure matches against, stay as built when they
    finished: a re-pass folded in a little off would blur their walls. Returns the submaps
    changed."""
    for k, cells, values in c.parts:
        g = k.grid
        np.add.at(g.log_odds, (cells[:, 0], cells[:, 1]), values.astype(np.float32))
        np.clip(g.log_odds, g.l_min, g.l_max, out=g.log_odds)
        r0, r1, c0, c1 = g.touched
        lo, hi = cells.min(axis=0), cells.max(axis=0) + 1
        g.touched = (
            min(r0, int(lo[0])),
            max(r1, int(hi[0])),
            min(c0, int(lo[1])),
            max(c1, int(hi[1])),
        )
    return [k for k, _, _ in c.parts]


def _overlaps(k: Submap, pose: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Whether the map-frame box of ``k``'s observed cells at ``pose`` meets the box lo..hi."""
    r0, r1, c0, c1 = k.grid.touched
    res = k.grid.resolution
    ox, oy = k.grid.origin
    corners = np.array([[ox + c * res, oy + r * res] for r in (r0, r1) for c in (c0, c1)])
    world = transform_points(pose, corners)
    return bool(np.all(world.min(axis=0) <= hi) and np.all(world.max(axis=0) >= lo))
