"""The submap trimmer: a robot that drives the same floor lap after lap keeps a bounded number of
submaps, and stays where it is."""

from __future__ import annotations

import math

import numpy as np
import pytest
from slam_sim import drifting_odometry, home_segments, loop_route, scan

from agents.slam.slam import Slam
from fleet.slam_params import SlamParams

LAPS = 4


@pytest.fixture(scope="module")
def drive():
    """LAPS laps round the flat's inner block; the SLAM's submaps kept after each."""
    segments = home_segments()
    lap = loop_route([(1.5, 1.0), (8.5, 1.0), (8.5, 5.0), (1.5, 5.0)], 0.4, 10.0)
    truth = np.concatenate([lap] * LAPS)
    odom = drifting_odometry(
        truth, heading_bias_per_m=0.004, trans_noise=0.02, rot_noise=0.02, seed=2
    )
    rng = np.random.default_rng(0)
    slam = Slam(SlamParams(), tuple(truth[0]), range_min=0.1, range_max=6.0, keep_trajectory=True)
    after_lap = []
    for k, (true_pose, odom_pose) in enumerate(zip(truth, odom, strict=True)):
        slam.process(*scan(segments, true_pose, rng=rng), tuple(odom_pose), 0.1 * k)
        if (k + 1) % len(lap) == 0:
            after_lap.append(slam.stats().submaps)
    slam.finish()
    return truth, slam, after_lap


def test_submaps_stay_bounded_over_laps(drive):
    _, slam, submaps = drive
    # past the first lap the map grows by at most a few submaps in all, not by a lap's worth
    assert submaps[-1] - submaps[1] <= 4, submaps
    assert slam.stats().trimmed > slam.stats().submaps


def test_trimmed_slam_stays_on_the_truth(drive):
    truth, slam, _ = drive
    final = slam.trajectory()
    err = np.hypot(*(final[:, :2] - truth[:, :2]).T)
    assert float(np.sqrt(np.mean(err**2))) < 0.05
    assert math.hypot(*(np.asarray(slam.pose[:2]) - truth[-1, :2])) < 0.05
