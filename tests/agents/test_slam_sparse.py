"""SLAM on a sparse log (issue 49 item 2): scans 1 m and 30° apart, made from the test flat's
segments, with odometry made by the noise recipe of ``data/slam/README.md``. SLAM must never be
worse than the odometry it starts from, on every seed, and must take at least 40 % off its RPE
over 20 scans and its ATE on the mean of the seeds.

One seed's figures are chaotic: an odometry moved by 1e-9 m moves the 180° scans' ATE on seed 2
between 0.54 and 0.79 of the odometry's (0.55 and 0.72 before the leaner refinement), so the
bound is on the mean. Today's means: RPE 20 and ATE at 0.17 and 0.19 of the odometry's with
360° scans, 0.47 and 0.54 with 180°. Broken on purpose, the SLAM fails this: a tracking window
of 2 cm and 0.01 rad (0.67 and 0.64 with 180°), no odometry prior in the search (ATE 1.00 × on
seed 2 with 180°); without the Gauss–Newton refinement it passes (0.47 and 0.56), which the
matcher's own tests catch."""

from __future__ import annotations

import math

import numpy as np
import pytest
from slam_sim import home_segments, scan

from agents.slam.evaluation import trajectory_scores
from agents.slam.slam import Slam
from fleet.bench.slam_log import noisy_odometry
from fleet.params import load_fleet_config


def sparse_route(laps: int = 3) -> np.ndarray:
    """Poses (T, 3) every 1 m around the flat's inner block (a 9 m × 5 m loop), the heading
    turned 30° further at every scan (a lidar that turns while the robot drives)."""
    corners = np.array([(0.5, 0.5), (9.5, 0.5), (9.5, 5.5), (0.5, 5.5), (0.5, 0.5)])
    edges = np.diff(corners, axis=0)
    lengths = np.hypot(edges[:, 0], edges[:, 1])
    s = np.arange(0.0, laps * lengths.sum(), 1.0) % lengths.sum()
    edge = np.searchsorted(np.cumsum(lengths), s, side="right")
    start = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])[edge]
    xy = corners[edge] + edges[edge] / lengths[edge, None] * (s - start)[:, None]
    heading = np.radians(30.0) * np.arange(len(s))
    return np.column_stack([xy, np.arctan2(np.sin(heading), np.cos(heading))])


def run_slam(truth: np.ndarray, odom: np.ndarray, seed: int, half_fov: bool) -> np.ndarray:
    """Live SLAM poses (T, 3) for scans taken at ``truth`` with ``odom`` as their odometry;
    ``half_fov`` keeps the front 180° of each scan, as a FLASER log holds."""
    cfg = load_fleet_config(None)
    rng = np.random.default_rng(100 + seed)
    slam = Slam(cfg.slam, tuple(odom[0]), range_min=0.05, range_max=6.0)
    live = []
    for k, (pose, odo) in enumerate(zip(truth, odom, strict=True)):
        ranges, angle_min, inc = scan(home_segments(), pose, rng=rng)
        if half_fov:
            ranges, angle_min = ranges[90:270], angle_min + 90 * inc
        est = slam.process(ranges, angle_min, inc, tuple(odo), float(k))
        live.append(est.pose)
    return np.array(live)


@pytest.mark.parametrize("half_fov", [False, True], ids=["360deg", "180deg"])
def test_slam_on_scans_1m_and_30deg_apart_is_never_worse_than_its_odometry(half_fov):
    truth = sparse_route()
    steps = np.diff(truth, axis=0)
    assert np.allclose(np.hypot(steps[:, 0], steps[:, 1]), 1.0, atol=0.3)
    assert np.allclose(np.abs(np.angle(np.exp(1j * steps[:, 2]))), math.radians(30), atol=1e-6)
    ratios = []
    for seed in (0, 1, 2):
        odom = noisy_odometry(truth, seed)
        live = run_slam(truth, odom, seed, half_fov)
        slam = trajectory_scores(live, truth)
        raw = trajectory_scores(odom, truth)
        for key in ("rpe1_m", "rpe5_m", "rpe20_m", "rpe5_deg", "rpe20_deg", "ate_m"):
            assert slam[key] <= raw[key], (seed, key, slam, raw)
        ratios.append([slam[key] / raw[key] for key in ("rpe20_m", "ate_m")])
    mean = np.mean(ratios, axis=0)
    assert np.all(mean <= 0.6), (ratios, mean)
