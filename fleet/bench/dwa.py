"""``fleet bench dwa``: how long one DWA control step (planners/dwa.py) takes with a full lidar
scan, and the clearance query alone with a cKDTree against a dense numpy distance matrix (the
baseline the planner's choice was measured against)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from fleet.params import FleetConfig
from planners.dwa import dwa_control, rollout

WARMUP_CALLS = 20
# the robot's speed (m/s, rad/s) while it is timed
VELOCITY = (0.3, 0.2)


def scene(beams: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A robot driving in a 5 × 4 m room with three round obstacles: its pose, its lidar hit
    points and its path."""
    pose = np.array([1.0, 0.6, 0.3])
    angles = pose[2] + np.arange(beams) * 2 * np.pi / beams
    d = np.column_stack([np.cos(angles), np.sin(angles)])
    with np.errstate(divide="ignore"):
        to_wall = np.where(d > 0, (np.array([5.0, 4.0]) - pose[:2]) / d, -pose[:2] / d)
    ranges = np.where(np.abs(d) > 1e-12, to_wall, np.inf).min(axis=1)
    circles = np.array([[2.2, 1.4, 0.3], [3.5, 0.8, 0.25], [1.8, 2.8, 0.4]])
    rel = pose[:2] - circles[:, :2]
    b = d @ rel.T
    disc = b**2 - ((rel**2).sum(axis=1) - circles[:, 2] ** 2)
    hits = np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0.0)), np.inf)
    ranges = np.minimum(ranges, np.where(hits > 0, hits, np.inf).min(axis=1))
    ranges += np.random.default_rng(0).normal(0.0, 0.01, beams)
    obstacles = pose[:2] + ranges[:, None] * d
    path = np.array([[1.0, 0.6], [2.0, 0.9], [2.9, 1.6], [4.2, 2.0], [4.4, 3.3]])
    return pose, obstacles, path


def _median_ms(fn: Callable[[], Any], n: int = 50) -> float:
    runs = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        runs.append(time.perf_counter() - t0)
    return float(np.median(runs) * 1e3)


def run_bench(cfg: FleetConfig, calls: int, beams: int) -> dict[str, Any]:
    """``calls`` timed DWA steps (after WARMUP_CALLS) with ``beams`` lidar points as obstacles,
    and the clearance query both ways; the figures."""
    params, robot, dt = cfg.dwa, cfg.robot, 1.0 / cfg.agent.control_hz
    pose, obstacles, path = scene(beams)

    def step() -> None:
        dwa_control(tuple(pose), VELOCITY, path, obstacles, params, robot, dt)

    for _ in range(WARMUP_CALLS):
        step()
    times = np.empty(calls)
    for i in range(calls):
        t0 = time.perf_counter()
        step()
        times[i] = time.perf_counter() - t0

    samples = params.vx_samples * params.vtheta_samples
    v = np.repeat(np.linspace(0.25, 0.35, params.vx_samples), params.vtheta_samples)
    w = np.tile(np.linspace(0.1, 0.3, params.vtheta_samples), params.vx_samples)
    steps = int(np.ceil(robot.max_vel_x * params.sim_time / params.sim_granularity - 1e-9))
    xs, ys, _ = rollout(tuple(pose), v, w, np.linspace(0.0, params.sim_time, steps + 1)[1:])
    points = np.column_stack([xs.ravel(), ys.ravel()])

    def kdtree() -> None:
        cKDTree(obstacles).query(points)

    def dense() -> None:
        diff = points[:, None, :] - obstacles[None, :, :]
        np.sqrt(np.einsum("pmk,pmk->pm", diff, diff).min(axis=1))

    kd_ms, dense_ms = _median_ms(kdtree), _median_ms(dense)
    median = float(np.median(times))
    return {
        "ms_per_call_median": round(median * 1e3, 3),
        "ms_per_call_p95": round(float(np.percentile(times, 95)) * 1e3, 3),
        "rollouts_per_s": round(samples / median),
        "samples": samples,
        "steps": steps,
        "obstacle_points": len(obstacles),
        "calls": calls,
        "clearance_kdtree_ms": round(kd_ms, 3),
        "clearance_dense_ms": round(dense_ms, 3),
        "kdtree_speedup": round(dense_ms / kd_ms, 1),
    }
