"""The escape move out of a dead end, and a robot without work keeping clear of its peers.

A robot that makes no progress under DWA for ``agent.escape_after_s`` — boxed in, or caught in
a minimum of DWA's costs — turns in place onto the free direction nearest its path and drives a
short way straight along it (:func:`escape_heading`, :func:`start_escape`,
:func:`escape_step`). A robot without work stands still unless a peer's intent comes at it,
and then steps aside with the same move (:func:`keep_clear`).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from agents.follow.primitives import gaps, held, kept_clear, rotate_in_place
from agents.follow.state import FollowParams, FollowState, Pose, Situation
from planners.dwa import DWAResult

ESCAPE_HEADINGS = 36
ESCAPE_MARGIN_M = 0.02
ESCAPE_HEADING_TOLERANCE = 0.05


def escape_heading(
    pose: Pose,
    aim: np.ndarray | None,
    obstacles: np.ndarray,
    peers: np.ndarray,
    robot_radius: float,
    distance: float,
) -> float | None:
    """The direction of travel of the escape move, or None when no straight move is free.

    Of ``ESCAPE_HEADINGS`` directions, the free ones are those along which a straight move of
    ``distance`` keeps every point at least min(robot_radius + ESCAPE_MARGIN_M, the gap now)
    clear of the obstacles and, judged apart, of the peers (see :func:`gaps`), and ends farther
    out than the robot is now (or clear of that margin); the one closest to the direction of
    ``aim`` wins, or without an aim the one that ends clearest. A disc robot can always turn in
    place, so any free direction can be taken: this is Nav2's Spin-then-DriveOnHeading recovery
    with the heading chosen from the scan instead of fixed, and it frees a robot from the
    pockets where DWA's forward arcs are all blocked and the way straight back is too."""
    xy = np.asarray(pose[:2], dtype=float)
    phi = np.linspace(-math.pi, math.pi, ESCAPE_HEADINGS, endpoint=False)
    if aim is not None:
        toward = math.atan2(aim[1] - xy[1], aim[0] - xy[0])
        off = np.abs(np.remainder(phi - toward + math.pi, 2 * math.pi) - math.pi)
    if len(obstacles) == 0 and len(peers) == 0:
        return float(phi[np.argmin(off)]) if aim is not None else None
    now = gaps(xy[None, :], obstacles, peers, robot_radius)
    gap_now = float(min(now[0][0], now[1][0]))
    steps = np.linspace(0.02, distance, 6)
    dirs = np.column_stack([np.cos(phi), np.sin(phi)])
    points = xy[None, None, :] + steps[None, :, None] * dirs[:, None, :]
    walls, robots = (
        g.reshape(len(phi), len(steps))
        for g in gaps(points.reshape(-1, 2), obstacles, peers, robot_radius)
    )
    along = np.minimum(walls, robots)
    margin = robot_radius + ESCAPE_MARGIN_M
    free = kept_clear(walls, robots, now, margin) & (
        (along[:, -1] > gap_now) | (along[:, -1] >= margin)
    )
    if not free.any():
        return None
    if aim is None:
        return float(phi[free][np.argmax(along[free, -1])])
    return float(phi[free][np.argmin(off[free])])


def start_escape(
    state: FollowState, now: Situation, aim: np.ndarray | None, params: FollowParams
) -> FollowState:
    """Begin the escape move toward ``aim`` (or to the clearest side, see
    :func:`escape_heading`), driving forward or in reverse, whichever needs the smaller turn
    first; the state is unchanged when no direction is free."""
    distance = params.agent.escape_distance
    travel = escape_heading(now.pose, aim, now.obstacles, now.peers, params.robot.radius, distance)
    if travel is None:
        return state
    forward = abs(math.remainder(travel - now.pose[2], 2 * math.pi)) <= math.pi / 2
    return replace(
        state,
        blocked_s=0.0,
        escape_m=distance,
        escape_heading=travel if forward else math.remainder(travel + math.pi, 2 * math.pi),
        escape_sign=1 if forward else -1,
    )


def escape_step(
    state: FollowState, now: Situation, params: FollowParams
) -> tuple[FollowState, DWAResult] | None:
    """One step of the escape move: turn in place onto ``state.escape_heading``, then drive
    straight (in reverse when ``escape_sign`` is −1) at ``escape_speed`` while ``escape_m`` is
    left and the way is clear — no point of it nearer the obstacles, or the peers (judged apart),
    than the robot radius or than the robot is now; None when the move is over or its way has
    closed."""
    pose, robot, dt = now.pose, params.robot, params.dt
    error = math.remainder(state.escape_heading - pose[2], 2 * math.pi)
    if abs(error) > ESCAPE_HEADING_TOLERANCE:
        return state, held(pose, *rotate_in_place(error, now.velocity, robot, dt), params.dwa)
    sign = state.escape_sign
    way = sign * np.array([math.cos(pose[2]), math.sin(pose[2])])
    ahead = np.asarray(pose[:2]) + np.linspace(0.02, state.escape_m, 5)[:, None] * way
    walls, robots = gaps(
        np.vstack([np.asarray(pose[:2])[None, :], ahead]), now.obstacles, now.peers, robot.radius
    )
    if not kept_clear(walls[1:], robots[1:], (walls[0], robots[0]), robot.radius):
        return None
    v0 = now.velocity[0]
    speed = params.agent.escape_speed
    v = min(max(sign * speed, v0 - robot.acc_lim_x * dt), v0 + robot.acc_lim_x * dt)
    result = held(pose, v, 0.0, params.dwa)
    left = state.escape_m - abs(v) * dt if v * sign > 0 else state.escape_m
    return replace(state, escape_m=max(0.0, left)), result


def keep_clear(
    state: FollowState, now: Situation, params: FollowParams
) -> tuple[FollowState, DWAResult]:
    """The step of a robot without work: stand still, unless a peer's intent (``now.peers``)
    comes within ``ESCAPE_MARGIN_M`` of its body — then step aside with the escape move, to the
    side that ends clearest. A robot that has finished its path would otherwise stand on someone
    else's."""
    robot, dt = params.robot, params.dt
    xy = np.asarray(now.pose[:2], dtype=float)
    if state.escape_m <= 0 and len(now.peers):
        d = np.hypot(*(now.peers - xy).T)
        if d.min() < 2 * robot.radius + ESCAPE_MARGIN_M:
            state = start_escape(state, now, None, params)
    if state.escape_m > 0:
        stepped = escape_step(state, now, params)
        if stepped is not None:
            return stepped
        state = replace(state, escape_m=0.0)
    v0, w0 = now.velocity
    v = max(0.0, v0 - robot.acc_lim_x * dt)
    w = min(max(0.0, w0 - robot.acc_lim_theta * dt), w0 + robot.acc_lim_theta * dt)
    return state, held(now.pose, v, w, params.dwa)
