"""Sweep tasks: the units of work the planner orders and splits among robots.

A task is a piece of one lane of a boustrophedon cell (or one cell's spiral, or a return
strip), with its ways to drive it: ``variants`` are paths, each of which may also be driven
backwards (the tour chooses).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from planners.coverage.bcd import MonotoneCell
from planners.coverage.frame import RotatedFrame
from planners.coverage.metrics import path_time
from planners.coverage.params import CoverageParams
from planners.coverage.sweeps import boustrophedon, eroded_sides, lane_rows, lanes_of
from planners.polyline import path_length, simplify
from planners.robot import RobotSpec


@dataclass(frozen=True, eq=False)
class SweepTask:
    """One task: ``variants`` are (N, 2) world paths covering the same lanes, each drivable in
    either direction."""

    room: int
    cell: int
    variants: tuple[np.ndarray, ...]
    area_m2: float
    time_s: float

    @property
    def centroid(self) -> np.ndarray:
        return self.variants[0].mean(axis=0)


def cell_tasks(
    room: int,
    cell_id: int,
    lanes: np.ndarray,
    frame: RotatedFrame,
    params: CoverageParams,
    robot: RobotSpec,
) -> list[SweepTask]:
    """The boustrophedon tasks of one cell over ``lanes`` ((n, 3) row coordinate, first and
    last column, sorted by row): every lane a task of its own, cut into pieces
    (``_lane_pieces``); the tour chooses their order and directions."""
    tasks = []
    for lane in lanes:
        tasks.extend(_lane_pieces(room, cell_id, lane, frame, params, robot))
    return tasks


def _lane_pieces(
    room: int,
    cell_id: int,
    lane: np.ndarray,
    frame: RotatedFrame,
    params: CoverageParams,
    robot: RobotSpec,
) -> list[SweepTask]:
    """One lane as tasks of at most ``params.max_lane_length``: equal pieces meeting at a cell
    centre, so driving them one after the other sweeps exactly what the whole lane does (each
    segment's brush rectangle is half-open), while the tour may also turn in the middle."""
    res = frame.resolution
    y, lo, hi = (float(v) for v in lane)
    n = max(1, math.ceil((hi - lo) * res / params.max_lane_length - 1e-9))
    cuts_all = np.unique(np.rint(np.linspace(lo, hi, n + 1)))
    spacing = params.lane_spacing(robot)
    tasks = []
    for a, b in itertools.pairwise(cuts_all):
        path = frame.to_world(np.array([[y, a], [y, b]]))
        length = (b - a) * res
        t = length / robot.max_vel_x
        tasks.append(SweepTask(room, cell_id, (path,), length * spacing, t))
    if len(cuts_all) == 1:
        path = frame.to_world(np.array([[y, lo], [y, hi]]))
        tasks.append(SweepTask(room, cell_id, (path,), res * spacing, 0.0))
    return tasks


def spiral_task(
    room: int,
    cell_id: int,
    cell: MonotoneCell,
    frame: RotatedFrame,
    params: CoverageParams,
    robot: RobotSpec,
) -> SweepTask:
    """An inward spiral over the cell: ring 0 runs along the outermost cells, ring j ≥ 1 along the
    cell eroded by ``j·step − ½`` cells (lanes between cell centres, like the boustrophedon
    lanes); the core too thin for another ring is swept by boustrophedon lanes.
    """
    res = frame.resolution
    step = max(1, math.floor(params.lane_spacing(robot) / res + 1e-9))
    parts: list[np.ndarray] = []
    j = 0
    while True:
        rows, left, right = eroded_sides(cell, j * step)
        if len(rows) <= step or np.any(np.diff(rows) != 1):
            break
        shift = 0.0 if j == 0 else 0.5
        parts.append(_ring(rows.astype(float), left - shift, right + shift, step, shift))
        j += 1
    rows, left, right = eroded_sides(cell, max(0, (j - 1) * step + 3) if j else 0)
    if len(rows) and not np.any(np.diff(rows) != 1):
        core = MonotoneCell(int(rows[0]), left, right)
        ys = lane_rows(core, params.lane_spacing(robot) / res)
        parts.append(boustrophedon(core, lanes_of(core, ys), True))
    world = _to_world(frame, np.vstack(parts), params)
    _, _, t = path_time(world, robot.max_vel_x, params.turn_cost_s, params.turn_angle_deg)
    return SweepTask(room, cell_id, (world,), cell.cells * res * res, t)


def _ring(rows: np.ndarray, left: np.ndarray, right: np.ndarray, step: int, shift: float):
    """One spiral ring: bottom edge, up the right side, top edge, down the left side to the
    row where the next ring begins."""
    bottom, top = rows[0] - shift, rows[-1] + shift
    down = np.arange(len(rows) - 1, min(step, len(rows) - 1) - 1, -1)
    return np.vstack(
        [
            [[bottom, left[0]], [bottom, right[0]]],
            np.stack([rows, right], axis=1),
            [[top, right[-1]], [top, left[-1]]],
            np.stack([rows[down], left[down]], axis=1),
        ]
    )


def _to_world(frame: RotatedFrame, rc: np.ndarray, params: CoverageParams) -> np.ndarray:
    return simplify(frame.to_world(rc), params.simplify_tolerance)


def strip_task(
    room: int,
    cell_id: int,
    strip: np.ndarray,
    frame: RotatedFrame,
    params: CoverageParams,
    robot: RobotSpec,
) -> SweepTask:
    """A return strip ((n, 2) (row, col) polyline, ``strips.return_strips``) as one task:
    cut into pieces, the tour would use them as connectors between lanes instead of as the
    way back."""
    path = _to_world(frame, strip, params)
    length = path_length(path)
    return SweepTask(
        room, cell_id, (path,), length * params.lane_spacing(robot), length / robot.max_vel_x
    )
