"""The correlative matcher recovers known offsets and reports an honest covariance."""

from __future__ import annotations

import math

import numpy as np
import pytest
from slam_sim import room_segments, scan

from agents.slam.geometry import scan_to_points, transform_points, wrap_angle
from agents.slam.matcher import CorrelativeMatcher, LikelihoodField, _coarse_bounds, _Window
from agents.slam.occupancy import LogOddsGrid
from fleet.slam_params import SlamParams

PARAMS = SlamParams()


def _grid(size: float = 16.0) -> LogOddsGrid:
    n = round(size / PARAMS.resolution)
    return LogOddsGrid(
        (n, n),
        (-size / 2, -size / 2),
        PARAMS.resolution,
        PARAMS.p_hit,
        PARAMS.p_miss,
        PARAMS.p_min,
        PARAMS.p_max,
    )


def _map_of(
    segments: np.ndarray, poses: list[tuple[float, float, float]], seed: int
) -> LikelihoodField:
    rng = np.random.default_rng(seed)
    grid = _grid()
    for pose in poses:
        pts = scan_to_points(*scan(segments, pose, rng=rng), 0.1, 6.0)
        grid.insert(np.array(pose[:2]), transform_points(np.array(pose), pts))
    return LikelihoodField(grid, PARAMS.match_sigma)


@pytest.fixture(scope="module")
def room_field() -> LikelihoodField:
    return _map_of(
        room_segments(), [(2.5, 2.0, 0.3), (3.0, 1.5, 1.0), (2.0, 3.0, -0.5), (4.0, 2.0, 2.0)], 0
    )


OFFSETS = [
    (0.3, 0.0, 0.0),
    (0.0, -0.3, 0.0),
    (0.0, 0.0, math.radians(15)),
    (0.0, 0.0, -math.radians(15)),
    (-0.3, 0.3, math.radians(15)),
    (0.25, -0.3, -math.radians(12)),
    (-0.12, -0.21, math.radians(7)),
]


@pytest.mark.parametrize("offset", OFFSETS)
@pytest.mark.parametrize("true_pose", [(2.7, 2.1, 0.2), (3.6, 1.2, -2.4), (1.4, 2.9, 1.3)])
def test_matcher_recovers_known_offset(room_field, true_pose, offset):
    rng = np.random.default_rng(7)
    truth = np.array(true_pose)
    points = scan_to_points(*scan(room_segments(), truth, rng=rng), 0.1, 6.0)
    prior = truth + np.array(offset)
    result = CorrelativeMatcher(PARAMS).match(
        room_field, points, prior, 0.35, math.radians(17), PARAMS.coarse_factor, penalize=False
    )
    assert math.hypot(*(result.pose[:2] - truth[:2])) < 0.03
    assert abs(wrap_angle(result.pose[2] - truth[2])) < math.radians(1.0)
    assert result.score > 0.8


def test_matcher_without_overlap_scores_low(room_field):
    """A scan from another place does not fit: the score is far below the acceptance level."""
    rng = np.random.default_rng(3)
    corridor = np.array([(-5.0, 0.0, 5.0, 0.0), (-5.0, 1.0, 5.0, 1.0)])
    points = scan_to_points(*scan(corridor, (0.0, 0.5, 0.0), rng=rng), 0.1, 6.0)
    result = CorrelativeMatcher(PARAMS).match(
        room_field, points, np.array([2.5, 2.0, 0.0]), 0.3, 0.2, 4, penalize=False
    )
    assert result.score < PARAMS.min_match_score


def test_covariance_is_long_along_a_corridor():
    """Olson §IV: in a featureless corridor the pose is uncertain along it, certain across it."""
    corridor = np.array([(-30.0, 0.0, 30.0, 0.0), (-30.0, 1.2, 30.0, 1.2)])
    fld = _map_of(corridor, [(0.0, 0.6, 0.0)], 1)
    rng = np.random.default_rng(2)
    points = scan_to_points(*scan(corridor, (0.1, 0.6, 0.0), rng=rng), 0.1, 6.0)
    result = CorrelativeMatcher(PARAMS).match(
        fld, points, np.array([0.1, 0.6, 0.0]), 0.3, 0.1, 4, penalize=False
    )
    var_x, var_y = result.covariance[0, 0], result.covariance[1, 1]
    assert var_x > 10 * var_y
    assert math.sqrt(var_y) < 0.02


def test_the_search_reads_cells_beyond_the_grid_as_its_edge():
    """Points that a shift puts off the grid are read at its edge (the field's forced-zero
    ring, the pooled level's edge), whether or not the window needs the clip; a window wholly
    inside needs none."""
    field = _map_of(room_segments(), [(2.5, 2.0, 0.3)], 0)
    rows, cols = field.shape
    points = np.array([[0.5, 0.0], [0.0, 1.5], [-2.0, 0.3]])
    for prior, leaves in (((0.0, 0.0, 0.1), False), ((-7.9, 7.9, 0.1), True)):
        window = _Window.around(field, points, np.array(prior), 0.1, 0.05, 0.008, (0.0, 0.0))
        assert window.leaves(field.shape, 4) is leaves
        coarse, starts, f = _coarse_bounds(field, window, 4)
        table = field.pooled(f)
        r = np.clip(window.row0[:, None, :] + starts[None, :, None], 0, rows - 1)
        c = np.clip(window.col0[:, None, :] + starts[None, :, None], 0, cols - 1)
        expected = table[r[:, :, None, :], c[:, None, :, :]].mean(axis=-1)
        np.testing.assert_allclose(coarse, expected - window.rot_penalty[:, None, None], atol=1e-6)
