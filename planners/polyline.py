"""Polyline tools: simplification and turn counting for planned and driven paths."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# a straight segment of a planned path at least this long (m) is a line the plan means (a lane,
# a hop round a door jamb), not a step of a grid's staircase: the simplification the tracker
# drives and the plan's time estimates see moves such a line's ends by at most
# LINE_TOLERANCE_M (m) (``simplify_indices``'s ``line``), which is what the tracker's check
# allows a path ahead nearer a wall than the plan's own (planners.dwa.MEDIAN_NOISE_M) ...
LINE_M = 0.2
LINE_TOLERANCE_M = 0.005
# ... unless the end's other segment is a grid step: shorter than twice the tolerance and
# turning by at least this much (rad) from the line (a staircase's steps are square or
# diagonal to its runs)
STEP_TURN_RAD = math.radians(30.0)


def simplify(points: np.ndarray, tolerance: float, line: float = math.inf) -> np.ndarray:
    """Ramer–Douglas–Peucker simplification (Douglas & Peucker 1973) of an (N, 2) polyline,
    its segments at least ``line`` long kept on their lines (see :func:`simplify_indices`)."""
    pts = np.asarray(points, dtype=float)
    return pts[simplify_indices(pts, tolerance, line)]


def simplify_indices(points: np.ndarray, tolerance: float, line: float = math.inf) -> np.ndarray:
    """The indices of the points :func:`simplify` keeps, in order (the first and the last
    among them). Iterative with an explicit stack; each split's point–line distances are one
    numpy call.

    Plain RDP bounds only the dropped points' distance from the chord, so it may drive a line
    of the plan up to ``tolerance`` off where the plan put it: a lane whose start lies within
    it of the chord that skips the start runs on a slant, a hop that bends round a door jamb
    is cut toward the jamb. So a vertex ending a segment at least ``line`` long is dropped only
    within ``LINE_TOLERANCE_M`` of the chord, unless its other segment is a grid step
    (``STEP_TURN_RAD``), which the simplification is there to absorb: each split is at the
    point farthest beyond its own tolerance.
    """
    pts = np.asarray(points, dtype=float)
    n = len(pts)
    if n < 3:
        return np.arange(n)
    tol = np.full(n, float(tolerance))
    if math.isfinite(line):
        d = np.diff(pts, axis=0)
        seg = np.hypot(d[:, 0], d[:, 1])
        heading = np.arctan2(d[:, 1], d[:, 0])
        turn = np.abs(np.remainder(heading[1:] - heading[:-1] + math.pi, 2 * math.pi) - math.pi)
        # the other segment at a vertex is a grid step: short and square or diagonal to the
        # line (a repeated point's turn is no measure: it is absorbed too)
        short = seg < 2 * tolerance
        squared = (turn >= STEP_TURN_RAD) | (seg[:-1] <= 1e-9) | (seg[1:] <= 1e-9)
        ends_line_before = (seg[:-1] >= line) & ~(short[1:] & squared)
        ends_line_after = (seg[1:] >= line) & ~(short[:-1] & squared)
        end = ends_line_before | ends_line_after
        tol[1:-1][end] = min(tolerance, LINE_TOLERANCE_M)
    keep = np.zeros(n, dtype=bool)
    keep[0] = keep[-1] = True
    stack = [(0, n - 1)]
    while stack:
        i, j = stack.pop()
        m = rdp_split(pts, i, j, tol)
        if m >= 0:
            keep[m] = True
            stack.append((i, m))
            stack.append((m, j))
    return np.flatnonzero(keep)


def rdp_split(pts: np.ndarray, i: int, j: int, tolerance: float | np.ndarray) -> int:
    """Where the Ramer–Douglas–Peucker simplification splits the stretch ``pts[i..j]``: the
    interior point farthest from the chord (from ``pts[i]`` if the chord has no length), or -1
    when none is farther than ``tolerance`` and only the ends are kept. With a tolerance per
    point (an array over ``pts``), the point farthest beyond its own."""
    if j - i < 2:
        return -1
    a, b = pts[i], pts[j]
    seg = b - a
    length = math.hypot(seg[0], seg[1])
    rel = pts[i + 1 : j] - a
    if length < 1e-12:
        dist = np.hypot(rel[:, 0], rel[:, 1])
    else:
        dist = np.abs(rel[:, 0] * seg[1] - rel[:, 1] * seg[0]) / length
    if np.ndim(tolerance):
        dist = dist - tolerance[i + 1 : j]
        tolerance = 0.0
    k = int(np.argmax(dist))
    return i + 1 + k if dist[k] > tolerance else -1


def without_straight_vertices(points: np.ndarray, tolerance_rad: float = 1e-6) -> np.ndarray:
    """The polyline without repeated points and without the interior vertices where it goes
    straight on (heading change at most ``tolerance_rad``): the same path in fewer points. A
    vertex where the path turns back on itself is kept, unlike in a simplification that
    measures distance to the line through the neighbours."""
    pts = without_repeats(points)
    if len(pts) < 3:
        return pts
    keep = np.ones(len(pts), dtype=bool)
    keep[1:-1] = heading_changes(pts) > tolerance_rad
    return pts[keep]


def without_repeats(points: np.ndarray) -> np.ndarray:
    """The polyline without repeated consecutive points (a copy)."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    keep = np.ones(len(pts), dtype=bool)
    keep[1:] = np.hypot(*np.diff(pts, axis=0).T) > 1e-9
    return pts[keep]


def ending_at(points: np.ndarray, end: np.ndarray | tuple[float, float]) -> np.ndarray:
    """The polyline run on to ``end``: ``end`` appended unless the points already end there."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    end = np.asarray(end, dtype=float)
    if len(pts) and np.allclose(pts[-1], end):
        return pts.copy()
    return np.vstack([pts, end[None]])


def heading_changes(points: np.ndarray) -> np.ndarray:
    """Absolute heading change (rad, in [0, π]) at each interior vertex of a polyline.

    Zero-length segments are dropped first, so repeated points do not count as turns.
    """
    pts = np.asarray(points, dtype=float)
    if len(pts) < 3:
        return np.zeros(0)
    d = np.diff(pts, axis=0)
    d = d[np.hypot(d[:, 0], d[:, 1]) > 1e-9]
    if len(d) < 2:
        return np.zeros(0)
    h = np.arctan2(d[:, 1], d[:, 0])
    dh = np.diff(h)
    return np.abs((dh + math.pi) % (2 * math.pi) - math.pi)


def count_turns(points: np.ndarray, min_angle_deg: float = 45.0) -> int:
    """Number of vertices where the heading changes by more than ``min_angle_deg``."""
    return int(np.count_nonzero(heading_changes(points) > math.radians(min_angle_deg)))


def path_length(points: np.ndarray) -> float:
    pts = np.asarray(points, dtype=float)
    if len(pts) < 2:
        return 0.0
    d = np.diff(pts, axis=0)
    return float(np.hypot(d[:, 0], d[:, 1]).sum())


def densify(path: np.ndarray, step: float) -> np.ndarray:
    """The path's vertices and points at most ``step`` apart along each of its segments."""
    seg = np.diff(path, axis=0)
    n = np.maximum(1, np.ceil(np.hypot(*seg.T) / step)).astype(int)
    i = np.repeat(np.arange(len(seg)), n)
    frac = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)) / n[i]
    return np.vstack([path[i] + frac[:, None] * seg[i], path[-1:]])


def cut_start(path: np.ndarray, cut: float) -> np.ndarray:
    """``path`` without its first ``cut`` metres."""
    seg = np.hypot(*np.diff(path, axis=0).T)
    ends = np.cumsum(seg)
    i = int(np.searchsorted(ends, cut, side="right"))
    before = ends[i] - seg[i]
    start = path[i] + (path[i + 1] - path[i]) * ((cut - before) / seg[i])
    return np.vstack([start, path[i + 1 :]])


@dataclass(frozen=True)
class _Turns:
    """Turns of a simplified stretch of polyline, with the headings of its first and last
    segments of non-zero length (None when it has none), so two stretches can be joined."""

    count: int
    first: float | None
    last: float | None


class TurnCounter:
    """``count_turns(simplify(points, tolerance), min_angle_deg)`` of a polyline that grows by
    appended points, without simplifying it again from scratch at every count.

    Ramer–Douglas–Peucker splits a stretch ``(i, j)`` of the polyline at the point farthest from
    its chord, and what it keeps between ``i`` and ``j`` depends on those points alone. Points
    are only appended, so each stretch's turns are remembered once worked out: a count after
    new points works out only the stretches that end at the newest point, and the ones whose
    split moved, and finds the rest remembered. The counts are exactly those of
    :func:`count_turns` on :func:`simplify`'s result.

    With ``stretch_points`` the polyline is cut into finished stretches of that many points
    (each one's last point the next one's first): a finished stretch is simplified on its own,
    its turns and end headings kept, its points and memo dropped, so memory stays bounded however
    long the path grows. The count then is that of the stretches simplified apart and joined
    (a turn at a join counts as at any vertex): each join is a vertex the whole path's
    simplification need not keep, and it changes how both stretches are split, so the count
    may differ from the whole path's by a few turns per join (on a soak run's tracks, 5 cm
    samples in stretches of 2000: 716 turns against 710 over 6 robots and 3 joins).
    """

    def __init__(
        self, tolerance: float, min_angle_deg: float = 45.0, stretch_points: int | None = None
    ) -> None:
        if stretch_points is not None and stretch_points < 3:
            raise ValueError(f"stretch_points must be at least 3, got {stretch_points}")
        self.tolerance = tolerance
        self.stretch_points = stretch_points
        self._min_angle = math.radians(min_angle_deg)
        self._pts = np.zeros((64, 2))
        self._n = 0
        self._appended = 0
        self._memo: dict[tuple[int, int], _Turns] = {}
        self._finished: _Turns | None = None
        self._counted = (0, 0)

    def __len__(self) -> int:
        """Points appended in all."""
        return self._appended

    def append(self, x: float, y: float) -> None:
        if self.stretch_points is not None and self._n >= self.stretch_points:
            self._finish_stretch()
        if self._n == len(self._pts):
            self._pts = np.vstack([self._pts, np.zeros_like(self._pts)])
        self._pts[self._n] = x, y
        self._n += 1
        self._appended += 1

    def points(self) -> np.ndarray:
        """The open stretch's points (the whole polyline without ``stretch_points``; a copy)."""
        return self._pts[: self._n].copy()

    def turns(self) -> int:
        if self._counted[0] != self._appended:
            n = self._n
            current = self._stretch(0, n - 1) if n >= 2 else _Turns(0, None, None)
            if self._finished is not None:
                current = self._join(self._finished, current)
            self._counted = (self._appended, current.count)
        return self._counted[1]

    def _finish_stretch(self) -> None:
        """Fold the open stretch into the finished turns; its last point starts the next."""
        done = self._stretch(0, self._n - 1)
        self._finished = done if self._finished is None else self._join(self._finished, done)
        self._pts[0] = self._pts[self._n - 1]
        self._n = 1
        self._memo.clear()

    def _stretch(self, first: int, last: int) -> _Turns:
        """The turns of stretch ``(first, last)``: splits worked out depth first, with an
        explicit stack (a spiral's simplification nests as deep as it has vertices)."""
        memo = self._memo
        splits: dict[tuple[int, int], int] = {}
        stack = [(first, last)]
        while stack:
            i, j = stack[-1]
            if (i, j) in memo:
                stack.pop()
                continue
            m = splits.get((i, j))
            if m is None:
                m = rdp_split(self._pts, i, j, self.tolerance)
                if m < 0:
                    memo[i, j] = self._segment(i, j)
                    stack.pop()
                    continue
                splits[i, j] = m
                stack.append((m, j))
                stack.append((i, m))
                continue
            stack.pop()
            memo[i, j] = self._join(memo[i, m], memo[m, j])
        return memo[first, last]

    def _segment(self, i: int, j: int) -> _Turns:
        dx, dy = self._pts[j] - self._pts[i]
        if math.hypot(dx, dy) <= 1e-9:
            return _Turns(0, None, None)
        h = math.atan2(dy, dx)
        return _Turns(0, h, h)

    def _join(self, a: _Turns, b: _Turns) -> _Turns:
        turn = 0
        if a.last is not None and b.first is not None:
            change = abs((b.first - a.last + math.pi) % (2 * math.pi) - math.pi)
            turn = int(change > self._min_angle)
        return _Turns(
            a.count + b.count + turn,
            a.first if a.first is not None else b.first,
            b.last if b.last is not None else a.last,
        )
