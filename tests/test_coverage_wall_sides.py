"""Passes along the walls a cell's lanes end at (planners.coverage.tasks.wall_side_tasks, and
the planner's ``wall_sides``): one per walled lane-end side, none along a side shared with a
neighbouring cell, and in a plan they sweep the scallops the lane ends leave."""

from __future__ import annotations

import dataclasses

import numpy as np
from coverage_maps import RES, boxed, grid_of

from planners.coverage import CoverageParams, plan_coverage
from planners.coverage.bcd import MonotoneCell
from planners.coverage.frame import RotatedFrame
from planners.coverage.metrics import swath
from planners.coverage.tasks import wall_side_tasks
from planners.grid import clearance

PARAMS = CoverageParams(overlap=0.1)
FRAME = RotatedFrame(0.0, (0.0, 0.0), RES, (20, 40))


def _cell(row0: int, rows: int, left: int, right: int) -> MonotoneCell:
    return MonotoneCell(row0, np.full(rows, left), np.full(rows, right))


def test_one_pass_along_each_walled_lane_end_side() -> None:
    centres = np.zeros(FRAME.shape, dtype=bool)
    centres[2:18, 3:30] = True
    tasks = wall_side_tasks(0, 1, _cell(2, 16, 3, 29), centres, FRAME, PARAMS)
    assert len(tasks) == 2
    xs = sorted(float(t.variants[0][:, 0].mean()) for t in tasks)
    assert np.allclose(xs, [3 * RES, 29 * RES])  # the columns of its lane ends
    for t in tasks:
        path = t.variants[0]
        assert np.ptp(path[:, 0]) < 1e-9 and np.ptp(path[:, 1]) > 0.7  # along the wall
        assert t.time_s > 0


def test_no_pass_along_a_side_shared_with_a_neighbouring_cell_or_too_short() -> None:
    centres = np.zeros(FRAME.shape, dtype=bool)
    centres[2:18, 3:30] = True  # the cell's right side goes on into the room: a neighbour
    left_only = wall_side_tasks(0, 1, _cell(2, 16, 3, 15), centres, FRAME, PARAMS)
    assert len(left_only) == 1 and float(left_only[0].variants[0][0, 0]) == 3 * RES
    short = _cell(2, 5, 3, 29)  # 0.25 m of wall: less than two lane spacings
    assert wall_side_tasks(0, 1, short, centres, FRAME, PARAMS) == []


def test_in_a_plan_they_sweep_the_band_along_the_lane_end_walls() -> None:
    """A 4 × 2.5 m room: its lanes end at the two short walls. With the side passes the band
    within 0.1 m of those walls is swept (on the plan's own grid), more than without."""
    g = grid_of(boxed(52, 82))
    start = [(2.0, 1.3)]

    def band_missed(params: CoverageParams) -> int:
        plan = plan_coverage(g, start, dataclasses.replace(params, fill_in=False))
        covered = np.zeros(g.shape, dtype=bool)
        for path in plan.paths:
            covered |= swath(g, path, params.cleaning_width / 2)[0]
        band = plan.cleanable & (clearance(g) < 0.1)
        return int((band & ~covered).sum())

    without = band_missed(PARAMS)
    with_sides = band_missed(dataclasses.replace(PARAMS, wall_sides=True))
    assert with_sides < without
