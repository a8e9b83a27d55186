"""Which scans become pose-graph nodes: after ``node_min_distance`` of travel or
``node_max_interval`` of time, and after ``node_min_rotation`` of turning only when the scanner
does not see all round. A full circle's scan turned on the spot shows the same walls, so a
robot turning in place (at every lane end) adds no node; a 180° scanner's turn shows it floor
it did not see, so it does."""

from __future__ import annotations

import math

import numpy as np
from slam_sim import room_segments, scan

from agents.slam.slam import Slam
from fleet.slam_params import SlamParams

PARAMS = SlamParams()
TURN_RATE = 1.0  # rad/s, the robot's in-place turn
RATE_HZ = 10.0


def _turn_in_place(half_fov: bool, seconds: float = 6.0) -> tuple[Slam, float]:
    """SLAM over a robot turning on the spot at (2.5, 2.0) in the test room, odometry exact;
    the largest heading error of its live pose (rad)."""
    rng = np.random.default_rng(4)
    slam = Slam(PARAMS, (2.5, 2.0, 0.0), range_min=0.05, range_max=6.0)
    worst = 0.0
    for k in range(int(seconds * RATE_HZ)):
        t = k / RATE_HZ
        pose = np.array([2.5, 2.0, TURN_RATE * t])
        ranges, angle_min, inc = scan(room_segments(), pose, rng=rng)
        if half_fov:  # the front half: -90° .. +90°
            ranges, angle_min = ranges[90:270], angle_min + 90 * inc
        est = slam.process(ranges, angle_min, inc, tuple(pose), t)
        err = (est.pose[2] - pose[2] + math.pi) % (2 * math.pi) - math.pi
        worst = max(worst, abs(err))
    return slam, worst


def test_a_full_circle_scanner_turning_in_place_adds_nodes_only_by_time_and_keeps_its_heading():
    slam, worst = _turn_in_place(half_fov=False)
    # the first scan, then one per node_max_interval (2 s) of the 6 s
    assert slam.stats().nodes <= 1 + math.ceil(6.0 / PARAMS.node_max_interval)
    assert worst < math.radians(0.5)


def test_a_half_circle_scanner_turning_in_place_adds_a_node_per_min_rotation():
    slam, worst = _turn_in_place(half_fov=True)
    # 0.1 rad a scan: a node every scan or every second one (a step of 0.1 rad in floating
    # point may fall just short of node_min_rotation)
    assert slam.stats().nodes >= TURN_RATE * 6.0 / PARAMS.node_min_rotation / 2
    assert worst < math.radians(0.5)


def test_driving_makes_a_node_every_min_distance_with_either_scanner():
    rng = np.random.default_rng(5)
    slam = Slam(PARAMS, (1.5, 2.0, 0.0), range_min=0.05, range_max=6.0)
    for k in range(20):  # 0.05 m a scan: 1 m
        pose = np.array([1.5 + 0.05 * k, 2.0, 0.0])
        ranges, angle_min, inc = scan(room_segments(), pose, rng=rng)
        slam.process(ranges, angle_min, inc, tuple(pose), k / RATE_HZ)
    assert 9 <= slam.stats().nodes <= 11
