"""The edge pass: a segment that runs beside a wall is driven by the wall follower on the scan.

DWA's obstacle cost keeps a robot a few centimetres farther from a wall than its lane, and its
pose estimate is centimetres off, so the band along walls went unswept. Where the segment the
robot is on runs beside a wall at about the wall follower's distance (:func:`wall_beside`), the
robot is steered by the wall follower instead (:mod:`planners.wall_follow`), held to the wall
it sees: the edge pass of a robot vacuum, and the brush reaches the wall.
"""

from __future__ import annotations

import math

import numpy as np

from agents.follow.primitives import gaps, held
from agents.follow.state import FollowParams, FollowState, Pose, Situation
from fleet.params import AgentParams
from planners.dwa import DWAResult, rollout
from planners.wall_follow import WallFollowParams, to_robot_frame, wall_follow_step

# wall_beside judges the wall along a segment in bins this long, and over at least this many
EDGE_BIN_M = 0.05
EDGE_MIN_BINS = 3
# the wall follower's command held this long (s) must keep this much (m) beyond the radius
EDGE_CHECK_S = 0.5
EDGE_MARGIN_M = 0.005


def wall_beside(
    state: FollowState,
    pose: Pose,
    obstacles: np.ndarray,
    wall: WallFollowParams,
    agent: AgentParams,
) -> int:
    """The side of the segment the robot is on (+1 left, −1 right) that runs along a wall at
    about the wall follower's distance, or 0.

    Beside the segment's stretch from ``edge_window`` behind the robot to ``edge_window`` ahead
    (up to its end), the scan's ``obstacles`` must line the segment at a lateral distance of
    at most ``wall.distance + edge_slack`` in at least ``edge_cover`` of its 5 cm bins (a
    wall the plan's lane hugs, not a door or the lane beyond an outside corner), and the robot
    must be on its way along the segment: heading within ``edge_heading`` of it and at most
    ``waypoint_tolerance`` beside it (DWA's obstacle cost may have pushed it a decimetre off a
    lane by a wall; the wall follower brings it back). Of two such sides (a corridor) the
    nearer wall is taken."""
    wps, i = state.waypoints, state.index
    if i == 0 or state.done:
        return 0
    start, seg = wps[i - 1], wps[i] - wps[i - 1]
    length = float(np.hypot(*seg))
    if length < 1e-9 or len(obstacles) == 0:
        return 0
    u = seg / length
    n = np.array([-u[1], u[0]])
    xy = np.asarray(pose[:2], dtype=float)
    along_robot = float((xy - start) @ u)
    heading_off = abs(math.remainder(pose[2] - math.atan2(u[1], u[0]), 2 * math.pi))
    if heading_off > agent.edge_heading or abs(float((xy - start) @ n)) > agent.waypoint_tolerance:
        return 0
    lo = max(0.0, along_robot - agent.edge_window)
    hi = min(length, along_robot + agent.edge_window)
    bins = int((hi - lo) / EDGE_BIN_M)
    if bins < EDGE_MIN_BINS:
        return 0
    rel = np.asarray(obstacles) - start
    along, beside = rel @ u, rel @ n
    near = (along >= lo) & (along < lo + bins * EDGE_BIN_M)
    best, best_gap = 0, math.inf
    for side in (1, -1):
        lateral = side * beside
        on = near & (lateral > 0) & (lateral <= wall.distance + agent.edge_slack)
        cover = np.unique(((along[on] - lo) / EDGE_BIN_M).astype(int)).size / bins
        if cover >= agent.edge_cover and (gap := float(np.median(lateral[on]))) < best_gap:
            best, best_gap = side, gap
    return best


def edge_step(
    state: FollowState, now: Situation, params: FollowParams, max_speed: float | None
) -> tuple[int, DWAResult | None]:
    """(side, command) of the wall follower on the segment the robot is on, capped at
    ``max_speed``; (0, None) without the edge pass (``params.wall`` None), where no wall runs
    beside the segment (:func:`wall_beside`), where a peer is within ``edge_peer_clear``, where
    the follower finds no wall on its scan, or where its command held for ``EDGE_CHECK_S`` would
    bring the robot nearer an obstacle than ``EDGE_MARGIN_M`` beyond its radius (or than it is
    now): DWA, which checks its rollouts, then drives (the wall follower turns a robot that
    meets its lane at an angle only within its angular acceleration, a few centimetres closer
    to the wall first). Near peers, DWA and its give-way keep the robots apart."""
    wall, robot, agent = params.wall, params.robot, params.agent
    if wall is None:
        return 0, None
    pose, obstacles, peers = now.pose, now.obstacles, now.peers
    xy = np.asarray(pose[:2], dtype=float)
    if len(peers) and float(np.hypot(*(peers - xy).T).min()) < agent.edge_peer_clear:
        return 0, None
    side = wall_beside(state, pose, obstacles, wall, agent)
    if not side:
        return 0, None
    points = to_robot_frame(obstacles, pose)
    command = wall_follow_step(points, side, now.velocity, wall, robot, params.dt, max_speed)
    if command is None:
        return 0, None
    xs, ys, _ = rollout(
        pose, np.array([command.v]), np.array([command.w]), np.linspace(0.0, EDGE_CHECK_S, 6)
    )
    clear, _ = gaps(np.column_stack([xs[0], ys[0]]), obstacles, np.zeros((0, 2)), robot.radius)
    if clear[1:].min() < min(robot.radius + EDGE_MARGIN_M, clear[0]):
        return 0, None
    return side, held(pose, command.v, command.w, params.dwa)
