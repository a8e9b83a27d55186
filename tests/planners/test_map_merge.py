"""Merging robots' maps by known transforms: frames, resampling and log-odds fusion."""

import math

import numpy as np
import pytest
from map_pieces import LIMITS, flat_segments, free_iou, piece, segment_floor, truth_on

from planners.map_merge import LogOddsMap, Transform2D, merge_maps

FLOOR = segment_floor(flat_segments())
BOUNDS = (-0.1, -0.1, 10.1, 7.1)
B_TO_A = Transform2D(0.37, -0.21, math.radians(7.0))


def test_transforms_compose_and_invert():
    t = Transform2D(1.0, -2.0, 0.7)
    u = Transform2D(-0.3, 0.5, -2.1)
    p = np.array([[0.4, 1.3], [-2.0, 0.1]])
    np.testing.assert_allclose(t.compose(u).apply(p), t.apply(u.apply(p)))
    np.testing.assert_allclose(t.inverse().apply(t.apply(p)), p, atol=1e-12)


def test_ros_cells_become_log_odds_with_unknown_at_zero():
    m = LogOddsMap.from_ros(np.array([[-1, 0, 50, 100]], dtype=np.int8), 0.05, (0.0, 0.0), LIMITS)
    np.testing.assert_allclose(m.log_odds, [[0.0, LIMITS[0], 0.0, LIMITS[1]]], atol=1e-6)
    g = m.to_gridmap(0.65, 0.35)
    assert g.unknown.tolist() == [[True, False, True, False]]
    assert g.occupied.tolist() == [[False, False, False, True]]


def test_a_quarter_turn_moves_every_cell_where_rot90_puts_it():
    rng = np.random.default_rng(0)
    lo = rng.normal(size=(6, 9)).astype(np.float32)
    m = LogOddsMap(lo, 0.1, (0.0, 0.0))
    # a quarter turn about the origin carries cell (r, c) (centre (c + .5, r + .5)·0.1) to the
    # point (−(r + .5), c + .5)·0.1: cell (c, 5 − r) of a grid whose columns start at −0.6
    merged = merge_maps([m], [Transform2D(0.0, 0.0, math.pi / 2)], (-10.0, 10.0))
    assert merged.origin == pytest.approx((-0.6, 0.0)) and merged.shape == (9, 6)
    assert merged.log_odds[2, 5 - 4] == pytest.approx(lo[4, 2], abs=1e-5)
    # rows grow with y, so that is np.rot90's clockwise turn of the array
    np.testing.assert_allclose(merged.log_odds, np.rot90(lo, k=-1), atol=1e-5)


def test_log_odds_add_where_maps_overlap_and_clamp():
    a = LogOddsMap(np.full((4, 4), 1.0, dtype=np.float32), 0.05, (0.0, 0.0))
    b = LogOddsMap(np.full((4, 4), 1.5, dtype=np.float32), 0.05, (0.0, 0.0))
    shifted = Transform2D(0.1, 0.0, 0.0)  # two cells to the right
    merged = merge_maps([a, b], [Transform2D.identity(), shifted], (-2.0, 2.0))
    assert merged.shape == (4, 6)
    np.testing.assert_allclose(merged.log_odds[0], [1.0, 1.0, 2.0, 2.0, 1.5, 1.5])


def test_two_halves_merged_by_their_start_poses_give_the_floors_free_space():
    a = piece(FLOOR, lambda xy: xy[..., 0] < 6.0, Transform2D.identity(), BOUNDS)
    b = piece(FLOOR, lambda xy: xy[..., 0] > 4.0, B_TO_A, BOUNDS)
    merged = merge_maps([a, b], [Transform2D.identity(), B_TO_A], LIMITS)
    grid = merged.to_gridmap(0.65, 0.35)
    truth = truth_on(FLOOR, merged)
    assert free_iou(grid, truth) > 0.98
    # the right half is there only through b's transform: without it, it is off
    wrong = merge_maps([a, b], [Transform2D.identity(), Transform2D.identity()], LIMITS)
    assert free_iou(wrong.to_gridmap(0.65, 0.35), truth_on(FLOOR, wrong)) < 0.9
