"""Tasks of the market: one coverage tour cut into pieces of about equal time, and remainders.

A tour is cut at its vertices. Each segment is judged by the floor it sweeps first along the
tour: its *new area* is the cleanable cells (``cell_labels > 0``) strictly within
``cleaning_width / 2`` of it that no earlier segment reached (the brush capsule of
:mod:`planners.coverage.metrics`), and its *hop* is the length it drives without sweeping new
floor, ``length − new area / cleaning_width`` (≈ 0 along a lane, ≈ the length on a transit
over swept floor). A boundary there splits no run of sweeping lanes, and the robot that wins
the next task may reach it by its own way instead of the hop.

The cut rule (sequential, from the start): with the elapsed estimated time ``T0`` at the last
cut and ``target_s`` the target, the path's rest becomes the last task once it is at most
``(1 + CUT_WINDOW) · target_s``. Otherwise the candidates are the interior vertices whose
estimated time lies within ``[T0 + (1 − CUT_WINDOW) · target_s, T0 + (1 + CUT_WINDOW) ·
target_s]``, and no later than ``CUT_WINDOW · target_s`` before the end (so the last task is
never a sliver). The cut goes to the candidate next to the longest hop when that hop is at
least ``HOP_M``, else (and among equal hops) to the candidate nearest ``T0 + target_s``; with
no candidate, to the vertex nearest ``T0 + target_s``. Estimated time at a vertex is the
robot's driving time so far by :func:`planners.drive_time.vertex_times`: it stops and turns in
place at the turns :func:`planners.coverage.metrics.path_time` counts (vertices of the
Ramer–Douglas–Peucker simplification turning by more than ``turn_angle_deg``), within the
robot's ``max_vel_theta`` and ``acc_lim_theta``, and drives the straight runs between them from
rest to rest within its ``max_vel_x`` and ``acc_lim_x``; each task's ``time_s`` is then that
time of its own path, so the turn at a cut belongs to neither task.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from planners.coverage.metrics import capsule, to_cells
from planners.coverage.params import CoverageParams
from planners.drive_time import profile_time, vertex_times
from planners.grid import GridMap
from planners.polyline import LINE_M, cut_start, heading_changes, simplify
from planners.robot import RobotSpec

# share of target_s a cut may fall before or after its target
CUT_WINDOW = 0.25
# a segment driving at least this many metres without sweeping new floor is a hop worth a cut
HOP_M = 0.5


# what a Task is for (see Task)
TASK_KINDS = ("tour", "frontier")


@dataclass(frozen=True, eq=False)
class Task:
    """A unit of work: a sweep path driven from path[0] to path[-1] (or reversed, see Bid).

    ``path`` is (N, 2) world metres, N ≥ 2, read-only; its N − 1 segments are its *pieces*
    (piece j is path[j] → path[j + 1]). ``area_m2`` is the cleanable floor its swath newly
    covers as planned, ``time_s`` its estimated driving time (stops, turns in place and
    rest-to-rest runs, see the module docstring), ``cells`` the ids of the boustrophedon cells
    whose floor it sweeps (sorted, unique). A remainder of ``"t07"`` is ``"t07.1"``, then
    ``"t07.2"``, of the same ``kind`` (``TASK_KINDS``): ``tour``, a piece of the coverage tour;
    ``frontier``, an exploring job's drive to a frontier. What a task is for is read from its
    kind, never from its id.
    """

    id: str
    path: np.ndarray
    area_m2: float
    time_s: float
    cells: tuple[int, ...]
    kind: str = "tour"

    def __post_init__(self) -> None:
        path = np.array(self.path, dtype=float)
        if path.ndim != 2 or path.shape[1] != 2 or len(path) < 2:
            raise ValueError(f"task {self.id}: path must be (N, 2) with N >= 2, got {path.shape}")
        if self.kind not in TASK_KINDS:
            raise ValueError(f"task {self.id}: kind {self.kind!r} is not one of {TASK_KINDS}")
        path.flags.writeable = False
        object.__setattr__(self, "path", path)

    @property
    def entry(self) -> np.ndarray:
        return self.path[0]

    @property
    def exit(self) -> np.ndarray:
        return self.path[-1]

    @property
    def pieces(self) -> int:
        return len(self.path) - 1


def split_tour(
    path: np.ndarray,
    cell_labels: np.ndarray,
    grid: GridMap,
    target_s: float,
    params: CoverageParams,
    robot: RobotSpec,
    prefix: str = "t",
) -> tuple[Task, ...]:
    """Cut one robot's coverage path at its vertices into consecutive tasks of about
    ``target_s`` estimated seconds each for ``robot``, preferring the long hops (the transits
    between sweeps) within a window around each target cut (the rule: module docstring).

    Every vertex of the path is in exactly one task, but for the cut vertices, which end one
    task and begin the next (task k's exit is task k + 1's entry). A task's time is its piece
    driven from rest to rest (:func:`task_time`) and the turn in place at its entry where the
    tour turns there: priced by neither piece alone, the turns at the cuts were missing from
    the tour's estimate (home: 929 s against 1019 s). Ids are ``prefix`` and a
    two-digit index ("t00", "t01", ...). A path shorter than ``target_s`` gives one task.
    ``cell_labels`` is the plan's grid-shaped image of boustrophedon cells (0 = none), whose
    non-zero cells are the cleanable floor.
    """
    if not target_s > 0:
        raise ValueError(f"target_s must be > 0, got {target_s}")
    pts = np.asarray(path, dtype=float)
    if pts.ndim != 2 or pts.shape[1:] != (2,) or len(pts) < 2:
        raise ValueError(f"path must be (N, 2) with N >= 2 points, got shape {pts.shape}")
    if cell_labels.shape != grid.shape:
        raise ValueError(
            f"cell_labels has shape {cell_labels.shape}, the grid {grid.shape}: not the plan's"
        )
    seg_len = np.hypot(*np.diff(pts, axis=0).T)
    new_cells, swept_labels, new_labels = _first_sweeps(pts, cell_labels, grid, robot)
    area = grid.resolution**2
    hop = np.maximum(seg_len - new_cells * area / robot.cleaning_width, 0.0)
    elapsed = _elapsed(pts, params, robot)
    cuts = _cuts(elapsed, hop, target_s)
    # the turn in place at a cut vertex is the next task's: a piece alone starts on its line
    stops, angles = _turns(pts, params)
    entry_turn = np.where(
        stops,
        profile_time(angles, robot.max_vel_theta, robot.acc_lim_theta),
        0.0,
    )
    tasks = []
    for k, (a, b) in enumerate(itertools.pairwise(cuts)):
        piece = pts[a : b + 1]
        cells = np.unique(np.concatenate(new_labels[a:b]))
        if len(cells) == 0:
            cells = np.unique(np.concatenate(swept_labels[a:b]))
        tasks.append(
            Task(
                id=f"{prefix}{k:02d}",
                path=piece,
                area_m2=float(new_cells[a:b].sum() * area),
                time_s=task_time(piece, params, robot) + float(entry_turn[a]),
                cells=tuple(int(c) for c in cells),
            )
        )
    return tuple(tasks)


def remainder(
    task: Task, swept: np.ndarray, new_id: str, params: CoverageParams, robot: RobotSpec
) -> Task | None:
    """The unswept rest of ``task``: ``swept`` is a bool array of length ``task.pieces``.

    The remainder's path runs from the start of the first unswept piece to the end of the last
    (swept pieces between them are driven again), its ``time_s`` is recomputed, its ``area_m2``
    is the task's scaled by the unswept share of the length (of the piece count for a path of
    zero length), its cells are the task's. None when every piece is swept.
    """
    done = np.asarray(swept, dtype=bool)
    if done.shape != (task.pieces,):
        raise ValueError(
            f"swept must have one flag per piece of task {task.id} ({task.pieces}), "
            f"got shape {done.shape}"
        )
    todo = np.flatnonzero(~done)
    if len(todo) == 0:
        return None
    path = task.path[todo[0] : todo[-1] + 2]
    seg_len = np.hypot(*np.diff(task.path, axis=0).T)
    total = float(seg_len.sum())
    share = float(seg_len[todo].sum()) / total if total > 0 else len(todo) / task.pieces
    return Task(
        new_id, path, task.area_m2 * share, task_time(path, params, robot), task.cells, task.kind
    )


def ahead_of(
    task: Task,
    xy: np.ndarray,
    reverse: bool,
    clearance: float,
    new_id: str,
    params: CoverageParams,
    robot: RobotSpec,
) -> Task | None:
    """What a robot driving ``task`` (backwards if ``reverse``) still had ahead of it when it
    stopped at ``xy``: the path from the point of it nearest ``xy`` on, less the first
    ``clearance`` metres (the floor beside a dead robot's body, which no robot can reach), in
    the task's own direction; time recomputed, area scaled by length. None if nothing is left.

    Finer than :func:`remainder`: a piece counts as swept only once its far end is reached, so a
    robot that dies near the end of a long lane would leave the whole lane — and a path into its
    own body — to the next one."""
    path = task.path[::-1] if reverse else task.path
    a, d = path[:-1], np.diff(path, axis=0)
    seg = np.hypot(*d.T)
    t = np.clip(
        ((np.asarray(xy, dtype=float) - a) * d).sum(axis=1) / np.maximum(seg**2, 1e-12), 0, 1
    )
    k = int(np.argmin(np.hypot(*(a + t[:, None] * d - xy).T)))
    at = float(seg[:k].sum() + t[k] * seg[k]) + clearance
    total = float(seg.sum())
    if at >= total - 1e-6:
        return None
    rest = cut_start(path, at)
    rest = rest[::-1] if reverse else rest
    share = (total - at) / total
    return Task(
        new_id, rest, task.area_m2 * share, task_time(rest, params, robot), task.cells, task.kind
    )


def task_time(path: np.ndarray, params: CoverageParams, robot: RobotSpec) -> float:
    """The estimated seconds ``robot`` takes to drive ``path`` from rest to rest (module
    docstring)."""
    return float(_elapsed(np.asarray(path, dtype=float), params, robot)[-1])


def _first_sweeps(
    pts: np.ndarray, cell_labels: np.ndarray, grid: GridMap, robot: RobotSpec
) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray]]:
    """Per segment: how many cleanable cells it sweeps first along the path, the cell labels
    under its whole swath, and those under the floor it sweeps first."""
    floor = cell_labels > 0
    covered = np.zeros(grid.shape, dtype=bool)
    hw = robot.cleaning_width / 2 / grid.resolution
    cells = to_cells(grid, pts)
    n = len(pts) - 1
    new_cells = np.zeros(n)
    swept_labels: list[np.ndarray] = []
    new_labels: list[np.ndarray] = []
    none = np.zeros(0, dtype=cell_labels.dtype)
    for j in range(n):
        at = capsule(cells[j], cells[j + 1], hw, grid.shape)
        if at is None:
            swept_labels.append(none)
            new_labels.append(none)
            continue
        window, mask, _ = at
        mine = mask & floor[window]
        new = mine & ~covered[window]
        covered[window] |= mine
        labels = cell_labels[window]
        new_cells[j] = np.count_nonzero(new)
        swept_labels.append(labels[mine])
        new_labels.append(labels[new])
    return new_cells, swept_labels, new_labels


def _elapsed(pts: np.ndarray, params: CoverageParams, robot: RobotSpec) -> np.ndarray:
    """Estimated seconds from the start to each vertex (:func:`planners.drive_time.vertex_times`):
    the robot stops and turns in place at the turns ``path_time`` counts, and drives each
    straight run between them from rest to rest within its ``max_vel_x`` and ``acc_lim_x``."""
    stops, angles = _turns(pts, params)
    return vertex_times(
        pts,
        stops,
        angles,
        robot.max_vel_x,
        robot.acc_lim_x,
        robot.max_vel_theta,
        robot.acc_lim_theta,
    )


def _turns(pts: np.ndarray, params: CoverageParams) -> tuple[np.ndarray, np.ndarray]:
    """The vertices ``path_time`` counts as turns (those of the simplified path whose heading
    changes by more than ``turn_angle_deg``) and the heading change at each vertex there."""
    simple = simplify(pts, params.simplify_tolerance, LINE_M)
    idx = _subsequence_indices(pts, simple)
    moved = np.concatenate([[True], np.hypot(*np.diff(simple, axis=0).T) > 1e-9])
    idx, simple = idx[moved], simple[moved]
    marks = np.zeros(len(pts), dtype=bool)
    angles = np.zeros(len(pts))
    if len(simple) >= 3:
        change = heading_changes(simple)
        angles[idx[1:-1]] = change
        marks[idx[1:-1]] = change > math.radians(params.turn_angle_deg)
    return marks, angles


def _subsequence_indices(pts: np.ndarray, sub: np.ndarray) -> np.ndarray:
    """Indices into ``pts`` of the points of ``sub``, a subsequence of it (equal copies)."""
    idx = np.zeros(len(sub), dtype=np.int64)
    i = 0
    for k, p in enumerate(sub):
        while not np.array_equal(pts[i], p):
            i += 1
        idx[k] = i
        i += 1
    return idx


def _cuts(elapsed: np.ndarray, hop: np.ndarray, target_s: float) -> list[int]:
    """Vertex indices of the task boundaries, first 0 and last the final vertex (module
    docstring: the rule)."""
    last = len(elapsed) - 1
    total = elapsed[-1]
    # the longest hop next to each vertex: the segment before it or the one after it
    near = np.zeros(len(elapsed))
    near[1:] = hop
    near[:-1] = np.maximum(near[:-1], hop)
    cuts = [0]
    while total - elapsed[cuts[-1]] > (1 + CUT_WINDOW) * target_s:
        t0 = elapsed[cuts[-1]]
        goal = t0 + target_s
        lo = t0 + (1 - CUT_WINDOW) * target_s
        hi = min(t0 + (1 + CUT_WINDOW) * target_s, total - CUT_WINDOW * target_s)
        inner = np.arange(cuts[-1] + 1, last)
        if len(inner) == 0:
            break
        t = elapsed[inner]
        cand = inner[(t >= lo) & (t <= hi)]
        if len(cand) == 0:
            cuts.append(int(inner[np.argmin(np.abs(t - goal))]))
            continue
        off = np.abs(elapsed[cand] - goal)
        best = near[cand].max()
        if best >= HOP_M:
            cand, off = cand[near[cand] == best], off[near[cand] == best]
        cuts.append(int(cand[np.argmin(off)]))
    cuts.append(last)
    return cuts
