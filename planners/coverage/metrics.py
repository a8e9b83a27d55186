"""Coverage metrics of any set of paths on a grid: what users of robot vacuums compare.

Definitions (cells are judged by their centres, so areas are counted in whole cells):

* **cleanable area** — the free cells within the swath of some robot-centre cell reachable from
  a start (``planners.grid.cleanable``): reachable centres dilated by a disc of radius
  ``cleaning_width / 2``. The cleaning swath, not the robot's body, is the footprint: a robot
  whose brush is narrower than its body never cleans the last few centimetres along a wall.
* **covered** — cleanable cells whose centre lies strictly within ``cleaning_width / 2`` of a
  path (the union of the capsules around its segments: the swath of a brush that is
  ``cleaning_width`` wide, including the disc swept when turning on the spot).
* **coverage** — covered cleanable cells / cleanable cells.
* **repetition** — a cell's visit count is the number of times it *enters* the brush disc
  (its centre comes strictly within ``cleaning_width / 2`` of the robot centre after being
  outside), the rule of the simulator's ground truth (``sim_server/cleaning.py``): a cell that
  stays under the brush while the robot turns is cleaned once, a cell the brush leaves and
  reaches again twice. Along a polyline that is, per segment, the cells of its capsule not
  already in the disc at its start (the first segment counts its whole capsule). Repetition =
  Σ visits / cells visited − 1: 0 when no cell is cleaned twice, 0.1 when on average a tenth
  is cleaned again. Summed over cells the visits are ≈ length · cleaning_width + π r²
  whatever the turns, so at a given coverage repetition measures excess path length.
* **turns** — vertices of the path simplified with tolerance ``simplify_tolerance``
  (Ramer–Douglas–Peucker) where the heading changes by more than ``turn_angle_deg``.
* **estimated time** — length / ``max_speed`` (the robot's top speed) + turns ·
  ``turn_cost_s``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from planners.coverage.params import CoverageParams
from planners.grid import GridMap, cleanable, inflate, reachable
from planners.polyline import LINE_M, count_turns, path_length, simplify
from planners.robot import RobotSpec

_PIECE_CELLS = 24.0


@dataclass(frozen=True)
class PathMetrics:
    """The table row of one path (or of all paths together, ``est_time_s`` being their max)."""

    coverage: float
    repetition: float
    path_length_m: float
    turns: int
    est_time_s: float
    covered_area_m2: float


@dataclass(frozen=True)
class CoverageMetrics:
    robots: tuple[PathMetrics, ...]
    total: PathMetrics
    makespan_s: float
    cleanable_area_m2: float
    unreachable_free_m2: float


def swath(grid: GridMap, path: np.ndarray, half_width: float) -> tuple[np.ndarray, np.ndarray]:
    """(covered, visits): cells within the capsules of ``path``, and per-cell visit counts.

    Long segments are cut into pieces of at most ``_PIECE_CELLS`` cells, which leaves both
    results unchanged (a cell in the disc at a cut is in both pieces' capsules and enters once).
    """
    covered = np.zeros(grid.shape, dtype=bool)
    visits = np.zeros(grid.shape, dtype=np.int32)
    pts = to_cells(grid, path)
    if len(pts) == 0:
        return covered, visits
    hw = half_width / grid.resolution
    if len(pts) == 1:
        _stamp(covered, visits, pts[0], pts[0], hw, first=True)
        return covered, visits
    first = True
    for a, b in itertools.pairwise(pts):
        n = max(1, math.ceil(math.hypot(*(b - a)) / _PIECE_CELLS))
        for k in range(n):
            _stamp(covered, visits, a + (b - a) * (k / n), a + (b - a) * ((k + 1) / n), hw, first)
            first = False
    return covered, visits


def to_cells(grid: GridMap, path: np.ndarray) -> np.ndarray:
    """World points → continuous (row, col) with cell centres at integers."""
    p = np.asarray(path, dtype=float).reshape(-1, 2)
    return (p[:, ::-1] - (grid.origin[1], grid.origin[0])) / grid.resolution - 0.5


def _stamp(covered, visits, a: np.ndarray, b: np.ndarray, hw: float, first: bool) -> None:
    """Add the segment a → b (continuous cells): its capsule to ``covered``, and to ``visits``
    the capsule's cells that enter the brush along it (all of them on the ``first`` segment,
    else those not already under the brush at ``a``)."""
    at = capsule(a, b, hw, covered.shape)
    if at is None:
        return
    window, cells, at_start = at
    covered[window] |= cells
    visits[window] += cells if first else cells & ~at_start


def capsule(
    a: np.ndarray, b: np.ndarray, hw: float, shape: tuple[int, int]
) -> tuple[tuple[slice, slice], np.ndarray, np.ndarray] | None:
    """The cells (continuous cell coordinates, centres at integers) strictly within ``hw`` of
    the segment a → b, and those within ``hw`` of ``a``, as masks over a window of a grid of
    ``shape`` (None when the window is empty)."""
    rows, cols = shape
    # scalar bounds in plain floats: this runs thousands of times per plan on small windows
    a0, a1, b0, b1 = float(a[0]), float(a[1]), float(b[0]), float(b[1])
    r0 = max(math.floor(min(a0, b0) - hw), 0)
    c0 = max(math.floor(min(a1, b1) - hw), 0)
    r1 = min(math.ceil(max(a0, b0) + hw) + 1, rows)
    c1 = min(math.ceil(max(a1, b1) + hw) + 1, cols)
    if r0 >= r1 or c0 >= c1:
        return None
    rr = np.arange(r0, r1, dtype=float)[:, None] - a0
    cc = np.arange(c0, c1, dtype=float)[None, :] - a1
    inner = hw**2 - 1e-9
    at_start = rr**2 + cc**2 < inner
    d0, d1 = b0 - a0, b1 - a1
    length = math.hypot(d0, d1)
    if length < 1e-9:
        cells = at_start
    else:
        t = (rr * d0 + cc * d1) / length
        np.clip(t, 0.0, length, out=t)
        cells = (rr - t * d0 / length) ** 2 + (cc - t * d1 / length) ** 2 < inner
    return (slice(r0, r1), slice(c0, c1)), cells, at_start


def path_time(
    path: np.ndarray,
    max_speed: float,
    turn_cost_s: float,
    turn_angle_deg: float = 45.0,
    simplify_tolerance: float = 0.03,
) -> tuple[float, int, float]:
    """(length m, turns, estimated seconds) of one path."""
    pts = np.asarray(path, dtype=float).reshape(-1, 2)
    length = path_length(pts)
    simple = simplify(pts, simplify_tolerance, LINE_M)
    turns = count_turns(simple, turn_angle_deg) if len(pts) > 2 else 0
    return length, turns, length / max_speed + turns * turn_cost_s


def coverage_metrics(
    grid: GridMap,
    paths: Sequence[np.ndarray],
    robot_radius: float,
    cleaning_width: float,
    *,
    max_speed: float,
    turn_cost_s: float = 2.0,
    turn_angle_deg: float = 45.0,
    simplify_tolerance: float = 0.03,
    cleanable_mask: np.ndarray | None = None,
) -> CoverageMetrics:
    """Metrics of ``paths`` (world metres, one (N, 2) array per robot) on ``grid``.

    The cleanable area is ``cleanable_mask`` if given, else computed from the first point of
    every non-empty path as the start (see the module docstring for every definition).
    """
    area = grid.resolution**2
    if cleanable_mask is None:
        starts = [np.asarray(p, dtype=float)[0] for p in paths if len(p)]
        blocked = inflate(grid, robot_radius)
        cells = grid.world_to_cell(np.array(starts)) if starts else np.zeros((0, 2), int)
        ok = grid.in_bounds(cells)
        cells = cells[ok]
        cells = cells[~blocked[cells[:, 0], cells[:, 1]]] if len(cells) else cells
        reach = reachable(~blocked, cells) if len(cells) else np.zeros(grid.shape, bool)
        cleanable_mask = cleanable(grid, reach, cleaning_width / 2)
    n_clean = int(cleanable_mask.sum())
    all_covered = np.zeros(grid.shape, dtype=bool)
    all_visits = np.zeros(grid.shape, dtype=np.int32)
    rows = []
    for p in paths:
        covered, visits = swath(grid, p, cleaning_width / 2)
        all_covered |= covered
        all_visits += visits
        length, turns, t = path_time(p, max_speed, turn_cost_s, turn_angle_deg, simplify_tolerance)
        rows.append(_row(covered, visits, cleanable_mask, n_clean, area, length, turns, t))
    makespan = max((r.est_time_s for r in rows), default=0.0)
    total = _row(
        all_covered,
        all_visits,
        cleanable_mask,
        n_clean,
        area,
        sum(r.path_length_m for r in rows),
        sum(r.turns for r in rows),
        makespan,
    )
    unreachable = float((grid.free & ~cleanable_mask).sum() * area)
    return CoverageMetrics(tuple(rows), total, makespan, n_clean * area, unreachable)


def plan_metrics(
    grid: GridMap,
    paths: Sequence[np.ndarray],
    params: CoverageParams,
    robot: RobotSpec,
    *,
    wall_clearance: float,
    cleanable_mask: np.ndarray | None = None,
) -> CoverageMetrics:
    """:func:`coverage_metrics` for ``robot`` (its centre kept ``wall_clearance`` more than its
    radius from obstacles, as :func:`planners.coverage.plan_coverage` plans it) with the turn
    and simplification figures of ``params``: how a plan and anything compared with it are
    judged."""
    return coverage_metrics(
        grid,
        paths,
        robot.radius + wall_clearance,
        robot.cleaning_width,
        max_speed=robot.max_vel_x,
        turn_cost_s=params.turn_cost_s,
        turn_angle_deg=params.turn_angle_deg,
        simplify_tolerance=params.simplify_tolerance,
        cleanable_mask=cleanable_mask,
    )


def _row(covered, visits, clean, n_clean, area, length, turns, t) -> PathMetrics:
    hit = int((covered & clean).sum())
    swept = int(np.count_nonzero(visits))
    repetition = float(visits.sum()) / swept - 1.0 if swept else 0.0
    return PathMetrics(
        coverage=hit / n_clean if n_clean else 0.0,
        repetition=repetition,
        path_length_m=float(length),
        turns=int(turns),
        est_time_s=float(t),
        covered_area_m2=hit * area,
    )


def missed_by_clearance(
    visits: np.ndarray, cleanable_cells: np.ndarray, clearance_m: np.ndarray, edges: Sequence[float]
) -> list[float]:
    """Where the missed floor lies: the cleanable cells never visited (``visits`` == 0; a
    boolean mask of the swept cells will do), as
    fractions of all cleanable cells, in bands of their clearance from the nearest obstacle
    (``clearance_m``, see :func:`planners.grid.clearance`) cut at ``edges`` (m, ascending).
    len(edges) + 1 fractions, summing to 1 − coverage: a band along walls and furniture that a
    lane or edge pass close to them sweeps, against gaps in the open floor between lanes."""
    if not (visits.shape == cleanable_cells.shape == clearance_m.shape):
        raise ValueError(
            f"visits {visits.shape}, cleanable {cleanable_cells.shape} and clearance "
            f"{clearance_m.shape} must be one shape"
        )
    total = int(cleanable_cells.sum())
    if total == 0:
        return [0.0] * (len(edges) + 1)
    missed = cleanable_cells & (visits == 0)
    band = np.digitize(clearance_m[missed], np.asarray(edges, dtype=float))
    return [float(n) / total for n in np.bincount(band, minlength=len(edges) + 1)]
