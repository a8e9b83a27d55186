"""What the follower's jobs share: a command chosen outside DWA, the turn in place, and the
clearance of the robot's body from the walls and, apart, from the peers."""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from agents.follow.state import Pose
from planners.dwa import DWAParams, DWAResult, rollout
from planners.robot import RobotSpec


def held(pose: Pose, v: float, w: float, params: DWAParams) -> DWAResult:
    """A command chosen outside DWA, with its trajectory over ``sim_time`` for the intent."""
    xs, ys, ths = rollout(pose, np.array([v]), np.array([w]), np.linspace(0, params.sim_time, 11))
    return DWAResult(v, w, np.column_stack([xs[0], ys[0], ths[0]]), 0.0, True)


def rotate_in_place(
    heading_error: float, velocity: tuple[float, float], robot: RobotSpec, dt: float
) -> tuple[float, float]:
    """(v, ω) that brakes to a stop and turns by ``heading_error``: the turn rate is the
    largest from which the robot can still stop on the heading, √(2·acc_lim_theta·|error|),
    capped at max_vel_theta and reached within the acceleration limits."""
    v0, w0 = velocity
    v = max(0.0, v0 - robot.acc_lim_x * dt)
    rate = min(robot.max_vel_theta, math.sqrt(2.0 * robot.acc_lim_theta * abs(heading_error)))
    dw = robot.acc_lim_theta * dt
    w = min(max(math.copysign(rate, heading_error), w0 - dw), w0 + dw)
    return v, w


def gaps(
    points: np.ndarray, obstacles: np.ndarray, peers: np.ndarray, robot_radius: float
) -> tuple[np.ndarray, np.ndarray]:
    """Clearance of a robot centred at each of ``points`` (P, 2), from the obstacle points and,
    apart, from the discs of other robots centred at ``peers`` (to their rims): two (P,)
    arrays, inf where there is nothing of that kind."""
    walls = np.full(len(points), np.inf)
    robots = np.full(len(points), np.inf)
    if len(obstacles):
        walls = cKDTree(obstacles).query(points)[0]
    if len(peers):
        robots = cKDTree(peers).query(points)[0] - robot_radius
    return walls, robots


def kept_clear(
    walls: np.ndarray, robots: np.ndarray, now: tuple[np.ndarray, np.ndarray], margin: float
) -> np.ndarray:
    """Whether each row of clearances (see :func:`gaps`) stays at least min(``margin``, the
    clearance now) from the walls and, judged apart, from the peers: a peer's disc that
    overlaps the robot must not license a move into a wall."""
    return (walls.min(axis=-1) >= np.minimum(margin, now[0])) & (
        robots.min(axis=-1) >= np.minimum(margin, now[1])
    )
