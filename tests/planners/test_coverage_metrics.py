"""Coverage metrics against values computed by hand on tiny grids, and visit counts against
entries of the brush counted by sampling the path densely."""

import itertools
import math

import numpy as np
import pytest
from coverage_maps import grid_of

from planners.coverage import coverage_metrics
from planners.coverage.metrics import missed_by_clearance, swath


def _open_grid(rows=7, cols=9):
    return grid_of(np.zeros((rows, cols), dtype=bool), res=1.0)


def test_one_straight_pass():
    g = _open_grid()
    path = np.array([[2.5, 3.5], [6.5, 3.5]])  # cell centres (row 3, col 2) → (row 3, col 6)
    covered, visits = swath(g, path, 1.5)
    # capsule: rows 2..4 × cols 1..7 (the end cells at √2 < 1.5 from the ends), each entered once
    assert covered.sum() == 21 and covered[2:5, 1:8].all()
    assert np.array_equal(visits, covered.astype(int))
    m = coverage_metrics(
        g, [path], 1.0, 3.0, max_speed=2.0, turn_cost_s=3.0, cleanable_mask=np.ones((7, 9), bool)
    )
    r = m.total
    assert math.isclose(r.coverage, 21 / 63)
    assert r.repetition == 0.0
    assert math.isclose(r.path_length_m, 4.0) and r.turns == 0
    assert math.isclose(r.est_time_s, 2.0)


def test_there_and_back_doubles_the_swept_cells():
    g = _open_grid()
    path = np.array([[2.5, 3.5], [6.5, 3.5], [2.5, 3.5]])
    m = coverage_metrics(
        g, [path], 1.0, 3.0, max_speed=2.0, turn_cost_s=3.0, cleanable_mask=np.ones((7, 9), bool)
    )
    # the 9 cells within 1.5 of the far end (cols 5..7) stay under the brush while it reverses:
    # entered once; the 12 cells of cols 1..4 are left and entered again → 33 / 21 − 1
    assert math.isclose(m.total.repetition, 33 / 21 - 1)
    assert m.total.turns == 1
    assert math.isclose(m.total.est_time_s, 8.0 / 2.0 + 3.0)


def test_two_robots_total_and_makespan():
    g = _open_grid()
    a = np.array([[2.5, 1.5], [6.5, 1.5]])
    b = np.array([[2.5, 5.5], [4.5, 5.5]])
    m = coverage_metrics(
        g, [a, b], 1.0, 3.0, max_speed=1.0, turn_cost_s=0.0, cleanable_mask=np.ones((7, 9), bool)
    )
    assert math.isclose(m.makespan_s, 4.0)
    assert math.isclose(m.robots[1].path_length_m, 2.0)
    # rows 0..2 and 4..6 swept once each: no repetition; row 3 untouched
    assert m.total.repetition == 0.0
    assert math.isclose(m.total.path_length_m, 6.0)


def test_swath_matches_brute_force_distance_on_a_diagonal():
    g = grid_of(np.zeros((30, 30), dtype=bool), res=0.1)
    path = np.array([[0.33, 0.41], [2.2, 1.7], [1.1, 2.6]])
    covered, _ = swath(g, path, 0.15)
    centres = g.cell_to_world(np.argwhere(np.ones((30, 30), bool))).reshape(30, 30, 2)
    dmin = np.full((30, 30), np.inf)
    for a, b in itertools.pairwise(path):
        d = b - a
        t = np.clip(((centres - a) @ d) / (d @ d), 0, 1)
        dmin = np.minimum(dmin, np.linalg.norm(centres - (a + t[..., None] * d), axis=-1))
    assert np.array_equal(covered, dmin < 0.15 - 1e-9)


def test_cleanable_area_from_the_path_starts_and_unreachable_space():
    occ = np.zeros((20, 40), dtype=bool)
    occ[:, 20] = True  # the right half is cut off from a start on the left
    g = grid_of(occ)
    m = coverage_metrics(g, [np.array([[0.5, 0.5], [0.6, 0.5]])], 0.17, 0.30, max_speed=0.5)
    assert m.cleanable_area_m2 > 0
    assert m.unreachable_free_m2 >= 19 * 20 * 0.05**2


def _entries_by_sampling(g, path, hw, step=0.002):
    """Per cell, how often its centre comes within ``hw`` of the path point after being
    farther: the path sampled every ``step`` metres."""
    pts = [path[:1]]
    for a, b in itertools.pairwise(path):
        n = max(1, math.ceil(np.hypot(*(b - a)) / step))
        pts.append(a + (b - a) * (np.arange(1, n + 1)[:, None] / n))
    pts = np.vstack(pts)
    centres = g.cell_to_world(np.argwhere(np.ones(g.shape, bool)))
    inside = np.linalg.norm(pts[:, None, :] - centres[None], axis=-1) < hw
    entered = inside[0].astype(int) + (inside[1:] & ~inside[:-1]).sum(axis=0)
    return entered.reshape(g.shape)


def test_visits_equal_the_brush_entries_along_turns_reversals_and_stops():
    g = grid_of(np.zeros((24, 24), dtype=bool), res=0.1)
    # a right angle, an acute turn, a reversal along the same line and a point repeated (a stop)
    path = np.array(
        [[0.43, 0.37], [1.71, 0.37], [1.71, 1.23], [0.52, 2.01], [1.63, 1.28], [1.63, 1.28]]
    )
    covered, visits = swath(g, path, 0.23)
    expected = _entries_by_sampling(g, path, 0.23)
    assert np.array_equal(visits, expected)
    assert np.array_equal(covered, expected > 0)
    assert visits.max() >= 2  # the reversal and the acute turn re-enter cells


def test_a_u_turn_between_lanes_cleans_the_corners_once():
    g = _open_grid(rows=10, cols=12)
    # two lanes 3 apart joined at their right ends: no cell is left and entered again
    path = np.array([[2.5, 2.5], [9.5, 2.5], [9.5, 5.5], [2.5, 5.5]])
    covered, visits = swath(g, path, 1.5)
    assert visits.max() == 1 and np.array_equal(visits, covered.astype(int))


def test_missed_floor_is_split_by_clearance_and_sums_to_what_coverage_misses() -> None:
    clearance_m = np.array([[0.05, 0.05, 0.2, 0.5], [0.05, 0.2, 0.5, 0.9]])
    cleanable_cells = np.array([[True, True, True, True], [False, True, True, True]])
    visits = np.array([[0, 3, 0, 1], [0, 1, 0, 0]])
    parts = missed_by_clearance(visits, cleanable_cells, clearance_m, (0.1, 0.3))
    # 7 cleanable cells; missed: one under 0.1 m (the uncleanable one does not count), one at
    # 0.2 m, two beyond 0.3 m
    assert parts == pytest.approx([1 / 7, 1 / 7, 2 / 7])
    covered = ((visits > 0) & cleanable_cells).sum() / cleanable_cells.sum()
    assert sum(parts) == pytest.approx(1 - covered)
    with pytest.raises(ValueError, match="one shape"):
        missed_by_clearance(visits[:1], cleanable_cells, clearance_m, (0.1,))
