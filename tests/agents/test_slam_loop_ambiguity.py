"""Loop closure along a wall that a raster map drew as a staircase: no closure slides the robot.

A wall a few degrees off the map's axes, as a recorded ROS map draws it, is a staircase of one
cell high steps every step length. A scan that sees mostly that wall fits an older submap as
well one step further along it as where it truly is, and where the scan reaches beyond what the
submap saw of the wall, the slid pose even scores higher (more of its points land on observed
wall). On a recorded apartment such closures moved the robot by whole steps (0.7 m) again and
again; the fix keeps a closure that moves the estimate by more than loop_agree_xy only when no
distinct candidate scores within loop_ambiguity_margin of it.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from slam_sim import mapped_grid, room_segments, scan

from agents.slam.geometry import scan_to_points
from agents.slam.matcher import CorrelativeMatcher, LikelihoodField
from agents.slam.slam import Slam
from fleet.slam_params import SlamParams

PARAMS = SlamParams()
STEP = 0.7  # step length of the staircase (m); each step is one 5 cm cell high


def _staircase(x0: float, x1: float) -> np.ndarray:
    """A wall from x0 to x1 rising one cell every STEP: treads and risers as segments."""
    segments = []
    y = 0.0
    for x in np.arange(x0, x1, STEP):
        segments.append((x, y, x + STEP, y))
        segments.append((x + STEP, y, x + STEP, y + PARAMS.resolution))
        y += PARAMS.resolution
    return np.array(segments)


def _route() -> np.ndarray:
    """Out along the staircase 0.15 m above it, back, and out again; 0.3 m/s, a scan every
    0.1 s."""
    xs = np.arange(0.0, 12.0, 0.03)
    out = np.stack([xs, 0.15 + xs * PARAMS.resolution / STEP, np.zeros_like(xs)], axis=1)
    back = out[::-1].copy()
    back[:, 2] = math.pi
    turn = np.array([(out[-1, 0], out[-1, 1], a) for a in np.linspace(0.0, math.pi, 20)])
    return np.concatenate([out, turn, back, out])


def _drive(params: SlamParams) -> tuple[np.ndarray, Slam]:
    """Drive the route with exact odometry; the per-scan position error of the estimate."""
    segments = _staircase(-8.0, 20.0)
    route = _route()
    rng = np.random.default_rng(0)
    # the map's cells are the raster the staircase was drawn on: its steps one cell each
    half = 0.5 * params.resolution
    slam = Slam(params, tuple(route[0]), range_min=0.1, range_max=6.0, lattice=(half, half))
    errors = []
    for k, pose in enumerate(route):
        est = slam.process(*scan(segments, pose, rng=rng), tuple(pose), 0.1 * k)
        errors.append(math.hypot(est.pose[0] - pose[0], est.pose[1] - pose[1]))
    return np.array(errors), slam


def _field(segments: np.ndarray, poses: list[tuple[float, float, float]]) -> LikelihoodField:
    return LikelihoodField(mapped_grid(segments, poses, PARAMS), PARAMS.match_sigma)


def _rival_gap(segments: np.ndarray, pose: tuple[float, float, float]) -> float:
    fld = _field(segments, [pose])
    points = scan_to_points(*scan(segments, np.array(pose), rng=np.random.default_rng(2)), 0.1, 6.0)
    result = CorrelativeMatcher(PARAMS).match(
        fld,
        points,
        np.array(pose),
        PARAMS.loop_window_xy,
        PARAMS.loop_window_theta,
        PARAMS.loop_coarse_factor,
        penalize=False,
        search_points=PARAMS.loop_search_points,
        distinct=(PARAMS.loop_agree_xy, PARAMS.loop_agree_theta),
        rival_margin=PARAMS.loop_ambiguity_margin,
    )
    return result.rival_gap


def test_rival_gap_is_small_along_a_staircase_and_large_in_a_furnished_room():
    """The matcher reports a second mode along the staircase, none in a furnished room."""
    assert _rival_gap(_staircase(-8.0, 8.0), (0.1, 0.4, 0.0)) < PARAMS.loop_ambiguity_margin
    assert _rival_gap(room_segments(), (2.7, 2.1, 0.2)) > PARAMS.loop_ambiguity_margin


@pytest.fixture(scope="module")
def runs() -> tuple[tuple[np.ndarray, Slam], tuple[np.ndarray, Slam]]:
    return _drive(PARAMS), _drive(dataclasses.replace(PARAMS, loop_ambiguity_margin=1e-9))


def test_no_closure_slides_the_robot_along_a_staircase_wall(runs):
    """Without the test (a margin of ~0) closures slide the estimate along the wall. (One drive
    is chaotic: over the lidar noise seeds 0–4 the unchecked drive's worst error was 0.11–0.19 m
    and the checked one's 0.04–0.08 m on 7a3bd22; with the leaner refinement, one rounding
    apart, 0.12–0.17 m and 0.04–0.07 m.)"""
    (errors, slam), (errors_unchecked, _) = runs
    assert errors_unchecked.max() > max(0.1, 1.5 * errors.max())
    assert errors.max() < 0.1
    assert slam.stats().loop_closures > 0
