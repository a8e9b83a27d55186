"""Return strips: a lane along the wall where the lanes end, so the way back is sweeping.

Under the brush-entry repetition metric (every metre driven sweeps ``cleaning_width`` of floor,
so at fixed coverage repetition is path length), the costly part of a boustrophedon in a
dead-end room is the return: the lanes end on the far side and the robot crosses the swept room
back to the door. A return strip takes one swath width off the lanes' ends on one side (where
they end against a wall) and sweeps it as a lane of its own, across the lanes through their old
end points: the floor swept is the same, the lanes are shorter by exactly the strip, and the
tour can sweep the lanes away from the door and come back along the strip.

Coordinates are a room's rotated frame (``lattice``): lanes ``(y, first col, last col)`` run
along rows, a strip is a polyline of (row, col) points, one per lane it crosses.
"""

from __future__ import annotations

import math

import numpy as np

# a strip crosses at least this many lanes (shorter ones cost a task for little return)
MIN_LANES = 3


def return_strips(
    lanes: list[np.ndarray], rot: np.ndarray, spacing: float, high: bool
) -> tuple[list[np.ndarray], list[list[np.ndarray]]]:
    """Per cell its lanes with the strips' width cut off their ends on one side (the last
    column's side when ``high``, else the first's), and per cell the strips as (n, 2) (row,
    col) polylines through the lanes' old end points.

    A strip runs half a column inside the old ends, over consecutive lanes (at most
    ``spacing`` rows apart) at least ``2·spacing`` long whose ends lie at most ``spacing``
    columns apart, as long as the straight segments between those ends stay on robot-centre
    cells of ``rot``; runs of fewer than ``MIN_LANES`` lanes are left alone. The lanes are
    shortened by ``spacing`` rounded down to whole columns (lane ends are cell centres), so
    strip and lanes overlap by at least the lanes' own overlap.
    """
    out_lanes = []
    out_strips = []
    end = 2 if high else 1
    step = math.floor(spacing + 1e-9)
    # half a column in: a lane end at a cell centre sweeps ``step − 1`` columns across, a line
    # between two columns exactly ``step``, meeting the shortened lanes' ends
    inward = -0.5 if high else 0.5
    for ln in lanes:
        ln = ln.copy()
        strips = []
        run: list[int] = []
        pts: list[tuple[float, float]] = []
        for i in range(len(ln) + 1):
            p = None
            if i < len(ln) and ln[i, 2] - ln[i, 1] >= 2 * spacing:
                p = (float(ln[i, 0]), float(ln[i, end] + inward))
            link = None
            if p is not None and run and ln[i, 0] - ln[run[-1], 0] <= spacing + 1e-9:
                link = _link(rot, pts[-1], p, spacing)
            if run and link is None:
                strips.append(_cut(ln, run, pts, end, step))
                run, pts = [], []
            if p is not None:
                run.append(i)
                pts.extend(link or [p])
        out_lanes.append(ln)
        out_strips.append([s for s in strips if s is not None])
    return out_lanes, out_strips


def _link(rot, a, b, spacing: float) -> list[tuple[float, float]] | None:
    """The strip's way from lane end ``a`` to the next lane's end ``b``: straight, or where
    the wall's staircase is in the way, along the first lane and then across; None if the
    ends are more than ``spacing`` apart along the lanes or neither way is clear."""
    if abs(a[1] - b[1]) > spacing:
        return None
    if _clear(rot, a, b):
        return [b]
    corner = (a[0], b[1])
    if _clear(rot, a, corner) and _clear(rot, corner, b):
        return [corner, b]
    return None


def _cut(ln: np.ndarray, run: list[int], pts: list, end: int, step: int) -> np.ndarray | None:
    """The strip through the run's lane ends (the lanes shortened in place), or None."""
    if len(run) < MIN_LANES:
        return None
    ln[run, end] += step if end == 1 else -step
    return np.array(pts, dtype=float)


def _clear(rot: np.ndarray, a: tuple[float, float], b: tuple[float, float]) -> bool:
    """Whether the segment a→b ((row, col), possibly half-integer) stays on ``rot``: every
    cell next to a point sampled every quarter cell along it is a robot-centre cell."""
    n = max(2, math.ceil(4 * math.hypot(b[0] - a[0], b[1] - a[1])) + 1)
    t = np.linspace(0.0, 1.0, n)
    r = a[0] + t * (b[0] - a[0])
    c = a[1] + t * (b[1] - a[1])
    fr, cr, fc, cc_ = np.floor(r), np.ceil(r), np.floor(c), np.ceil(c)
    rr = np.concatenate([fr, cr, fr, cr]).astype(int)
    cc = np.concatenate([fc, fc, cc_, cc_]).astype(int)
    inside = (rr >= 0) & (rr < rot.shape[0]) & (cc >= 0) & (cc < rot.shape[1])
    return bool(inside.all() and rot[rr, cc].all())
