"""Sweep tasks: the units of work the planner orders and splits among robots.

A task is a piece of one lane of a boustrophedon cell (or a return strip), with its ways to
drive it: ``variants`` are paths, each of which may also be driven
backwards (the tour chooses).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from planners.coverage.frame import RotatedFrame
from planners.coverage.params import CoverageParams
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
