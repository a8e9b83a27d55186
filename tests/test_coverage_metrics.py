"""Coverage metrics against values computed by hand on tiny grids."""

import itertools
import math

import numpy as np
from coverage_maps import grid_of

from planners.coverage import coverage_metrics
from planners.coverage.metrics import swath


def _open_grid(rows=7, cols=9):
    return grid_of(np.zeros((rows, cols), dtype=bool), res=1.0)


def test_one_straight_pass():
    g = _open_grid()
    path = np.array([[2.5, 3.5], [6.5, 3.5]])  # cell centres (row 3, col 2) → (row 3, col 6)
    covered, passes = swath(g, path, 1.5)
    # rectangle: cols 2..5 (half-open along the segment) × rows 2..4; capsule: cols 1..7
    assert passes.sum() == 12 and passes.max() == 1
    assert covered.sum() == 21 and covered[2:5, 1:8].all()
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
    # back pass sweeps cols 6..3: passes 24 over the 15 cells of cols 2..6 → 24 / 15 − 1
    assert math.isclose(m.total.repetition, 24 / 15 - 1)
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
    m = coverage_metrics(g, [np.array([[0.5, 0.5], [0.6, 0.5]])], 0.17, 0.30)
    assert m.cleanable_area_m2 > 0
    assert m.unreachable_free_m2 >= 19 * 20 * 0.05**2
