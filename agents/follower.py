"""Following a waypoint path with DWA: the agent's pure control step.

The agent keeps an index of the next waypoint; a waypoint counts as reached when the robot is
within ``waypoint_tolerance`` of it or has passed it (its projection on the segment into the
waypoint lies beyond the waypoint). DWA is given the local path from the previous waypoint on,
a few metres long, so its path-distance cost keeps the robot on the lane, not merely near the
next point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from planners.dwa import DWAParams, DWAResult, dwa_control

LOCAL_PATH_M = 3.0
PROGRESS_M = 0.02
MEDIAN_BEAMS = 5


@dataclass(frozen=True)
class FollowState:
    waypoints: np.ndarray
    index: int = 0
    stalled_s: float = 0.0
    best_dist: float = math.inf

    @property
    def done(self) -> bool:
        return self.index >= len(self.waypoints)


def advance(
    state: FollowState, xy: np.ndarray, tolerance: float, goal_tolerance: float
) -> FollowState:
    """Skip the waypoints the robot at ``xy`` has reached or passed."""
    wps, i = state.waypoints, state.index
    n = len(wps)
    while i < n:
        tol = goal_tolerance if i == n - 1 else tolerance
        if math.dist(xy, wps[i]) <= tol:
            i += 1
            continue
        if 0 < i < n - 1:
            seg = wps[i] - wps[i - 1]
            length2 = float(seg @ seg)
            if length2 > 1e-12 and float((xy - wps[i - 1]) @ seg) / length2 > 1.0:
                i += 1
                continue
        break
    return FollowState(wps, i) if i != state.index else state


def local_path(state: FollowState, xy: np.ndarray, horizon_m: float = LOCAL_PATH_M) -> np.ndarray:
    """The path ahead: the segment the robot is on and the waypoints up to ``horizon_m``."""
    wps, i = state.waypoints, state.index
    pts = [wps[i - 1]] if i > 0 else [xy]
    length = 0.0
    for j in range(i, len(wps)):
        length += math.dist(pts[-1], wps[j])
        pts.append(wps[j])
        if length >= horizon_m:
            break
    return np.array(pts, dtype=float)


def scan_points(
    pose: tuple[float, float, float],
    ranges: np.ndarray,
    angle_min: float,
    angle_increment: float,
) -> np.ndarray:
    """World-frame obstacle points of a scan; each range is a 5-beam median to damp noise."""
    r = np.asarray(ranges, dtype=float)
    half = MEDIAN_BEAMS // 2
    padded = np.concatenate([r[-half:], r, r[:half]])
    windows = np.lib.stride_tricks.sliding_window_view(padded, MEDIAN_BEAMS)
    r = np.median(windows, axis=1)
    ok = np.isfinite(r)
    a = pose[2] + angle_min + angle_increment * np.nonzero(ok)[0]
    return np.column_stack([pose[0] + r[ok] * np.cos(a), pose[1] + r[ok] * np.sin(a)])


def control_step(
    state: FollowState,
    pose: tuple[float, float, float],
    velocity: tuple[float, float],
    obstacles: np.ndarray,
    params: DWAParams,
    robot_radius: float,
    dt: float,
    tolerance: float,
    goal_tolerance: float,
    give_up_s: float,
) -> tuple[FollowState, DWAResult | None]:
    """Advance along the path and choose a command; ``None`` when the path is finished.

    A waypoint the robot has come no closer to (by ``PROGRESS_M``) for ``give_up_s`` is
    skipped, so a robot whose way is shut, that is caught in a local minimum of the DWA costs,
    or whose pose estimate has drifted into a wall moves on instead of waiting forever; the
    skipped spot stays uncleaned and shows in the coverage.
    """
    xy = np.array(pose[:2])
    state = advance(state, xy, tolerance, goal_tolerance)
    if state.done:
        return state, None
    result = dwa_control(pose, velocity, local_path(state, xy), obstacles, params, robot_radius, dt)
    dist = math.dist(xy, state.waypoints[state.index])
    if dist < state.best_dist - PROGRESS_M:
        return replace(state, stalled_s=0.0, best_dist=dist), result
    if state.stalled_s + dt >= give_up_s:
        return FollowState(state.waypoints, state.index + 1), result
    return replace(state, stalled_s=state.stalled_s + dt), result
