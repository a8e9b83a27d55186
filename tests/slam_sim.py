"""A tiny 2D world for SLAM tests: rooms made of line segments, a vectorized lidar ray caster,
the rooms' occupancy raster, a loop route with drifting odometry, and a driver for SimCore."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np

from agents.pose_source import PoseSource
from agents.slam.geometry import compose, relative, scan_to_points, transform_points, wrap_angle
from agents.slam.occupancy import LogOddsGrid
from fleet.slam_params import SlamParams
from sim_server.core import SimCore


def box(x0: float, y0: float, x1: float, y1: float) -> list[tuple[float, float, float, float]]:
    return [(x0, y0, x1, y0), (x1, y0, x1, y1), (x1, y1, x0, y1), (x0, y1, x0, y0)]


def room_segments() -> np.ndarray:
    """A 6 m × 4 m room with an alcove and three pieces of furniture (no symmetry to fool a
    matcher)."""
    walls = [
        (0.0, 0.0, 6.0, 0.0),
        (6.0, 0.0, 6.0, 2.5),
        (6.0, 2.5, 5.0, 2.5),
        (5.0, 2.5, 5.0, 4.0),
        (5.0, 4.0, 0.0, 4.0),
        (0.0, 4.0, 0.0, 0.0),
    ]
    return np.array(
        walls + box(1.0, 1.0, 1.6, 1.4) + box(3.5, 2.8, 4.2, 3.3) + box(4.5, 0.6, 4.8, 1.2)
    )


def home_segments() -> np.ndarray:
    """Two rooms joined by a corridor (a 10 m × 6 m flat), for a loop with drift."""
    walls = [
        (0.0, 0.0, 10.0, 0.0),
        (10.0, 0.0, 10.0, 6.0),
        (10.0, 6.0, 0.0, 6.0),
        (0.0, 6.0, 0.0, 0.0),
        # inner block: the loop goes around it
        (3.0, 2.0, 7.0, 2.0),
        (7.0, 2.0, 7.0, 4.0),
        (7.0, 4.0, 3.0, 4.0),
        (3.0, 4.0, 3.0, 2.0),
        # partition walls with doorways to break the symmetry
        (5.0, 0.0, 5.0, 0.7),
        (8.5, 6.0, 8.5, 5.4),
    ]
    return np.array(
        walls + box(0.4, 0.4, 0.9, 1.0) + box(8.8, 0.3, 9.6, 0.8) + box(1.0, 5.2, 2.2, 5.6)
    )


def ring_segments() -> np.ndarray:
    """A 16 m × 10 m ring of 2 m wide corridors around a solid block. The bottom corridor is
    featureless: mid-way, both its ends are beyond a 6 m lidar, so scans fix the position across
    it but not along it and odometry drift leaks into the estimate until the loop is closed. The
    other corridors have a sawtooth outer wall that pins the position along them."""
    walls = [(0.0, 0.0, 16.0, 0.0), (2.0, 2.0, 14.0, 2.0), (14.0, 2.0, 14.0, 8.0)]
    walls += [(14.0, 8.0, 2.0, 8.0), (2.0, 8.0, 2.0, 2.0)]
    xs = np.arange(16.0, -0.01, -0.5)
    top = [(x, 10.0 if i % 2 == 0 else 9.7) for i, x in enumerate(xs)]
    ys = np.arange(0.0, 10.01, 0.5)
    right = [(16.0 if i % 2 == 0 else 15.7, y) for i, y in enumerate(ys)]
    left = [(0.0 if i % 2 == 0 else 0.3, y) for i, y in enumerate(ys[::-1])]
    for line in (right, top, left):
        walls += [(a[0], a[1], b[0], b[1]) for a, b in itertools.pairwise(line)]
    return np.array(walls)


def raycast(
    segments: np.ndarray, pose: np.ndarray, angles: np.ndarray, max_range: float
) -> np.ndarray:
    """Range along each beam to the nearest segment; ``inf`` where nothing is within max_range."""
    ox, oy, th = pose
    dx = np.cos(th + angles)[:, None]
    dy = np.sin(th + angles)[:, None]
    ax, ay, bx, by = (segments[:, i][None, :] for i in range(4))
    ex, ey = bx - ax, by - ay
    denom = dx * ey - dy * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((ax - ox) * ey - (ay - oy) * ex) / denom
        u = ((ax - ox) * dy - (ay - oy) * dx) / denom
    hit = (np.abs(denom) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
    t = np.where(hit, t, np.inf).min(axis=1)
    return np.where(t < max_range, t, np.inf)


def scan(
    segments: np.ndarray,
    pose: np.ndarray,
    beams: int = 360,
    max_range: float = 6.0,
    noise: float = 0.01,
    rng: np.random.Generator | None = None,
) -> tuple[np.ndarray, float, float]:
    """A 360° scan (ranges, angle_min, angle_increment) with Gaussian range noise."""
    inc = 2 * math.pi / beams
    angles = -math.pi + inc * np.arange(beams)
    r = raycast(segments, np.asarray(pose, dtype=float), angles, max_range)
    if rng is not None and noise > 0:
        r = r + rng.normal(0.0, noise, size=r.shape)
    return r, -math.pi, inc


def mapped_grid(
    segments: np.ndarray, poses: Sequence[tuple[float, float, float]], params: SlamParams
) -> LogOddsGrid:
    """A 20 m × 20 m grid about the origin holding one scan (1 cm noise, seeded) from each of
    ``poses``, inserted at its true pose: a submap as the SLAM would fill it."""
    n = 400
    grid = LogOddsGrid(
        (n, n),
        (-10.0, -10.0),
        params.resolution,
        params.p_hit,
        params.p_miss,
        params.p_min,
        params.p_max,
    )
    rng = np.random.default_rng(1)
    for pose in poses:
        pts = scan_to_points(*scan(segments, np.array(pose), rng=rng), 0.1, 6.0)
        grid.insert(np.array(pose[:2]), transform_points(np.array(pose), pts))
    return grid


def occupancy_raster(
    segments: np.ndarray, resolution: float, origin: tuple[float, float], shape: tuple[int, int]
) -> np.ndarray:
    """Cells (row 0 = lowest y) that a wall segment passes through."""
    out = np.zeros(shape, dtype=bool)
    for ax, ay, bx, by in segments:
        n = math.ceil(math.hypot(bx - ax, by - ay) / (resolution / 4)) + 1
        s = np.linspace(0.0, 1.0, n)
        col = np.floor((ax + s * (bx - ax) - origin[0]) / resolution).astype(int)
        row = np.floor((ay + s * (by - ay) - origin[1]) / resolution).astype(int)
        ok = (row >= 0) & (row < shape[0]) & (col >= 0) & (col < shape[1])
        out[row[ok], col[ok]] = True
    return out


def loop_route(waypoints: list[tuple[float, float]], speed: float, rate_hz: float) -> np.ndarray:
    """Poses (T, 3) along a closed polyline at ``speed``, turning in place at the corners at
    0.8 rad/s, sampled at ``rate_hz``."""
    pts = [*waypoints, waypoints[0]]
    poses = []
    heading = math.atan2(pts[1][1] - pts[0][1], pts[1][0] - pts[0][0])
    for (x0, y0), (x1, y1) in itertools.pairwise(pts):
        target = math.atan2(y1 - y0, x1 - x0)
        turn = float(wrap_angle(target - heading))
        for k in range(int(abs(turn) / (0.8 / rate_hz))):
            poses.append(
                (x0, y0, float(wrap_angle(heading + math.copysign(k * 0.8 / rate_hz, turn))))
            )
        heading = target
        n = max(int(math.hypot(x1 - x0, y1 - y0) / (speed / rate_hz)), 1)
        for k in range(n):
            f = k / n
            poses.append((x0 + f * (x1 - x0), y0 + f * (y1 - y0), heading))
    poses.append((*pts[-1], heading))
    return np.array(poses)


def drifting_odometry(
    truth: np.ndarray,
    heading_bias_per_m: float,
    trans_noise: float,
    rot_noise: float,
    seed: int,
    scale_bias: float = 0.0,
) -> np.ndarray:
    """Odometry poses accumulated from true increments with a systematic heading bias per metre
    travelled, a distance scale error (wheel radius) and noise proportional to each increment."""
    rng = np.random.default_rng(seed)
    odom = [truth[0].copy()]
    for a, b in itertools.pairwise(truth):
        d = relative(a, b)
        dist = math.hypot(d[0], d[1])
        noisy = d + np.array(
            [
                scale_bias * d[0] + rng.normal(0, trans_noise * dist),
                scale_bias * d[1] + rng.normal(0, trans_noise * dist),
                heading_bias_per_m * dist + rng.normal(0, rot_noise * abs(d[2]) + 1e-4),
            ]
        )
        odom.append(compose(odom[-1], noisy))
    return np.array(odom)


def drive_sim(core: SimCore, source: PoseSource, commands: Sequence, robot: str = "r") -> None:
    """Step the simulator through (seconds, v, w) commands to ``robot``, feeding its odometry
    and scans to ``source``."""
    for seconds, v, w in commands:
        core.set_cmd(robot, v, w)
        end = core.t + seconds
        while core.t < end - 1e-9:
            out = core.step()
            for _, msg in out.odometry:
                source.on_odometry(msg)
            for _, msg in out.scans:
                source.on_scan(msg)
