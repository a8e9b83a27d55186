"""Return strips: lanes shortened on one side, the strip sweeping what they gave up."""

from __future__ import annotations

import numpy as np
import pytest
from coverage_maps import boxed, grid_of
from robots import ROBOT

from planners.coverage import CoveragePlan, plan_coverage
from planners.coverage import plan as coverage_plan
from planners.coverage.metrics import swath
from planners.coverage.params import CoverageParams
from planners.coverage.strips import MIN_LANES, return_strips
from planners.polyline import path_length

STEP = 6
HW = 0.15


def _lanes(n: int, lo: int = 3, hi: int = 56) -> np.ndarray:
    return np.array([(2.5 + STEP * k, lo, hi) for k in range(n)], dtype=float)


def _swept(paths: list[np.ndarray], shape: tuple[int, int]) -> np.ndarray:
    grid = grid_of(np.zeros(shape, dtype=bool))
    out = np.zeros(shape, dtype=bool)
    for rc in paths:
        out |= swath(grid, grid.cell_to_world(rc), HW)[0]
    return out


def test_a_strip_sweeps_exactly_what_it_takes_off_the_lanes():
    rot = np.ones((40, 60), dtype=bool)
    lanes = _lanes(6)
    for high in (False, True):
        clipped, strips = return_strips([lanes], rot, STEP, high)
        end = 2 if high else 1
        assert len(strips[0]) == 1
        cut = clipped[0][:, end] - lanes[:, end]
        assert np.all(cut == (-STEP if high else STEP))
        strip = strips[0][0]
        assert np.allclose(strip[:, 0], lanes[:, 0])
        assert np.allclose(strip[:, 1], lanes[:, end] + (-0.5 if high else 0.5))
        before = _swept([np.array([[y, a], [y, b]]) for y, a, b in lanes], rot.shape)
        after = _swept([np.array([[y, a], [y, b]]) for y, a, b in clipped[0]] + [strip], rot.shape)
        # between the first and the last lane as much floor, the same but for the corners the
        # round lane ends miss: the strip takes those at the wall, leaves those at the new ends
        rows = slice(int(lanes[0, 0]) + 1, int(lanes[-1, 0]))
        assert before[rows].sum() == after[rows].sum()
        differ = np.argwhere(before[rows] != after[rows])[:, 1]
        assert np.all(np.abs(differ - strip[0, 1]) <= STEP)


def test_no_strip_across_an_obstacle_or_over_too_few_lanes():
    rot = np.ones((40, 60), dtype=bool)
    rot[10:12, 2:6] = False
    clipped, strips = return_strips([_lanes(6)], rot, STEP, False)
    # the obstacle splits the run into 2 + 4 lanes: only the second gets a strip
    assert len(strips[0]) == 1 and len(strips[0][0]) == 6 - 2
    assert np.all(clipped[0][:2, 1] == 3) and np.all(clipped[0][2:, 1] == 3 + STEP)
    few = _lanes(MIN_LANES - 1)
    clipped, strips = return_strips([few], np.ones((40, 60), dtype=bool), STEP, True)
    assert strips == [[]] and np.array_equal(clipped[0], few)


def _hall_and_dead_end_room():
    """A 3 m × 5 m hall and a 3 m × 5 m room behind a 0.7 m door."""
    occ = boxed(100, 122)
    occ[:, 61] = True
    occ[5:19, 61] = False
    return grid_of(occ)


def _no_strips(
    lanes: list[np.ndarray], rot: np.ndarray, spacing: float, high: bool
) -> tuple[list[np.ndarray], list[list[np.ndarray]]]:
    """``return_strips`` finding room for no strip: every room planned from its plain lanes."""
    return lanes, [[] for _ in lanes]


def _rooms_with_a_strip(plan: CoveragePlan, params: CoverageParams) -> set[int]:
    """The rooms with a return strip: a task across the room's lanes, longer than a lane's
    pieces may be (``params.max_lane_length``)."""
    rooms = set()
    for task in (t for ts in plan.tasks for t in ts):
        path = task.variants[0]
        angle = plan.room_graph.nodes[task.room]["angle"]
        along = abs((path[-1] - path[0]) @ np.array([np.cos(angle), np.sin(angle)]))
        if path_length(path) > params.max_lane_length and along < 0.1 * path_length(path):
            rooms.add(task.room)
    return rooms


def test_strips_shorten_the_path_through_dead_end_rooms_at_the_same_coverage(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Hall and room have one neighbour each, so both are dead ends: both get a strip, and the
    plan is shorter, at the same coverage, than the one made where no lanes allow a strip."""
    grid = _hall_and_dead_end_room()
    params = CoverageParams()
    with_strips = plan_coverage(grid, [(0.8, 1.5)], params, ROBOT, wall_clearance=0.0)
    assert _rooms_with_a_strip(with_strips, params) == set(with_strips.room_graph.nodes)
    monkeypatch.setattr(coverage_plan, "return_strips", _no_strips)
    without = plan_coverage(grid, [(0.8, 1.5)], params, ROBOT, wall_clearance=0.0)
    assert not _rooms_with_a_strip(without, params)
    ours, plain = with_strips.metrics.total, without.metrics.total
    assert ours.coverage >= 0.995 and plain.coverage >= 0.995
    # the final pruning also cuts back the plain plan's lane ends, so strips gain less than
    # they did before it (3.5 m in a 3.5 m deep room then, 2 m in this 5 m deep one now)
    assert ours.path_length_m < plain.path_length_m - 1.0
    assert ours.repetition < plain.repetition
