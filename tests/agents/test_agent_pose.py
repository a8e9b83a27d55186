"""The agent's pose sources and its map messages, without a bus."""

from __future__ import annotations

import math

import numpy as np
import pytest
from slam_sim import drifting_odometry, loop_route, room_segments, scan

from agents.map_keeper import map_message
from agents.pose_source import OdometryPose, SlamPose, odometry_at
from agents.slam.slam_map import PatchTracker
from fleet.protocol import LaserScan, MapPatches, Odometry, decode, encode
from fleet.slam_params import SlamParams

RATE_HZ = 10.0


def _drive(source, truth: np.ndarray, odom: np.ndarray, seed: int = 1) -> np.ndarray:
    """Feed odometry and scans as the agent does (odometry first, then the scan of that time);
    return the source's pose after each scan."""
    rng = np.random.default_rng(seed)
    segments = room_segments()
    out = []
    for k, (true_pose, odom_pose) in enumerate(zip(truth, odom, strict=True)):
        t = k / RATE_HZ
        source.on_odometry(Odometry(t, *map(float, odom_pose), 0.0, 0.0))
        ranges, a0, inc = scan(segments, true_pose, rng=rng)
        source.on_scan(LaserScan(t, a0, inc, 0.1, 6.0, ranges.astype(np.float32)))
        out.append(source.pose())
    return np.array(out)


def _route() -> tuple[np.ndarray, np.ndarray]:
    truth = loop_route([(0.7, 0.5), (4.2, 0.5), (4.2, 2.2), (2.5, 3.4), (0.7, 3.4)], 0.3, RATE_HZ)
    odom = drifting_odometry(truth, 0.02, 0.02, 0.02, seed=3)
    return truth, odom


def test_slam_pose_stays_on_truth_where_odometry_drifts() -> None:
    truth, odom = _route()
    start = tuple(float(v) for v in truth[0])
    slam = _drive(SlamPose(SlamParams(), start, 0.1, 6.0), truth, odom)
    dead = _drive(OdometryPose(start), truth, odom)
    slam_err = np.hypot(*(slam[:, :2] - truth[:, :2]).T)
    odom_err = np.hypot(*(dead[:, :2] - truth[:, :2]).T)
    assert odom_err.max() > 0.15
    assert slam_err.max() < 0.05
    assert np.sqrt(np.mean(slam_err**2)) < 0.25 * np.sqrt(np.mean(odom_err**2))


def test_slam_pose_follows_odometry_between_scans_and_reports_covariance() -> None:
    truth, odom = _route()
    src = SlamPose(SlamParams(), tuple(float(v) for v in truth[0]), 0.1, 6.0)
    _drive(src, truth[:30], odom[:30])
    at_scan = src.pose()
    cov = src.covariance()
    assert cov.shape == (9,) and np.all(np.diag(cov.reshape(3, 3)) >= 0)
    last = odom[29]
    moved = (last[0] + 0.1 * math.cos(last[2]), last[1] + 0.1 * math.sin(last[2]), last[2])
    src.on_odometry(Odometry(3.05, *moved, 0.0, 0.0))
    after = src.pose()
    assert math.dist(at_scan[:2], after[:2]) == pytest.approx(0.1, abs=1e-6)
    assert src.occupancy() is not None
    assert OdometryPose((0.0, 0.0, 0.0)).occupancy() is None


def test_map_messages_rebuild_the_map_exactly() -> None:
    truth, odom = _route()
    src = SlamPose(SlamParams(), tuple(float(v) for v in truth[0]), 0.1, 6.0)
    tracker = PatchTracker(SlamParams().map_tile, 0)
    received: np.ndarray | None = None
    for chunk in range(0, len(truth), 40):
        _drive(src, truth[chunk : chunk + 40], odom[chunk : chunk + 40], seed=chunk)
        snapshot = src.occupancy()
        msg = decode(
            encode(map_message(0.0, chunk, SlamParams().map_tile, tracker.update(snapshot))),
            MapPatches,
        )
        if msg.full or received is None or received.shape != (msg.rows, msg.cols):
            received = np.full((msg.rows, msg.cols), -1, np.int8)
        t = msg.tile
        for r, c, block in zip(msg.patch_rows, msg.patch_cols, msg.blocks, strict=True):
            received[r : r + t, c : c + t] = block
        np.testing.assert_array_equal(received, snapshot.to_ros())
    assert received is not None and (received >= 65).sum() > 100


def test_odometry_at_interpolates_along_the_motion_and_clamps_outside() -> None:
    history = [(0.0, (0.0, 0.0, 0.0)), (1.0, (1.0, 1.0, math.pi / 2))]
    # half way: half the relative motion, composed onto the first pose
    assert odometry_at(history, 0.5) == pytest.approx((0.5, 0.5, math.pi / 4))
    backing = [(0.0, (0.0, 2.0, math.pi / 2)), (1.0, (0.0, 1.0, math.pi / 2))]  # in reverse
    assert odometry_at(backing, 0.25) == pytest.approx((0.0, 1.75, math.pi / 2))
    assert odometry_at(history, 1.0) == history[1][1]
    assert odometry_at(history, -1.0) == history[0][1]
    assert odometry_at(history, 2.0) == history[1][1]
