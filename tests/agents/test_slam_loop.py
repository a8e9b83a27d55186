"""Loop closure: after a lap with drifting odometry the SLAM end pose agrees with the start."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from slam_sim import drifting_odometry, loop_route, ring_segments, scan

from agents.slam.geometry import relative
from agents.slam.slam import Slam
from fleet.slam_params import SlamParams


def _lap(params: SlamParams) -> tuple[np.ndarray, np.ndarray, Slam]:
    """One lap of the corridor ring; odometry over-counts distance by 3 % and drifts in heading.
    In the featureless corridor the scale error leaks into the SLAM estimate (the scans cannot
    tell where along it the robot is), which only a loop closure can undo."""
    segments = ring_segments()
    truth = loop_route([(1.0, 1.0), (15.0, 1.0), (15.0, 9.0), (1.0, 9.0)], 0.4, 10.0)
    odom = drifting_odometry(
        truth, heading_bias_per_m=0.004, trans_noise=0.02, rot_noise=0.02, seed=1, scale_bias=0.03
    )
    rng = np.random.default_rng(0)
    slam = Slam(params, tuple(truth[0]), range_min=0.1, range_max=6.0, keep_trajectory=True)
    for k, (true_pose, odom_pose) in enumerate(zip(truth, odom, strict=True)):
        slam.process(*scan(segments, true_pose, rng=rng), tuple(odom_pose), 0.1 * k)
    slam.finish()
    return truth, odom, slam


def _end_to_start_error(poses: np.ndarray, truth: np.ndarray) -> float:
    """How far the estimated start-to-end motion is from the true one (the robot is back)."""
    est = relative(poses[0], poses[-1])
    true = relative(truth[0], truth[-1])
    return math.hypot(est[0] - true[0], est[1] - true[1])


@pytest.fixture(scope="module")
def laps():
    with_loops = _lap(SlamParams())
    no_loops = _lap(dataclasses.replace(SlamParams(), loop_min_score=0.999))
    return with_loops, no_loops


def test_odometry_alone_drifts(laps):
    (truth, odom, _), _ = laps
    assert _end_to_start_error(odom, truth) > 0.5


def test_loop_closure_reduces_end_to_start_error(laps):
    (truth, _, closed), (_, _, open_) = laps
    assert closed.stats().loop_closures > 0 and closed.stats().optimizations > 0
    assert open_.stats().loop_closures == 0
    err_closed = _end_to_start_error(closed.trajectory(), truth)
    err_open = _end_to_start_error(open_.trajectory(), truth)
    assert err_closed < 0.5 * err_open
    assert err_closed < 0.06


def test_trajectory_after_loop_closure_is_close_to_truth(laps):
    (truth, _, closed), _ = laps
    err = np.hypot(*(closed.trajectory()[:, :2] - truth[:, :2]).T)
    assert np.sqrt(np.mean(err**2)) < 0.1
