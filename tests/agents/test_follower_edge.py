"""The edge pass in the path follower: a lane that hugs a wall is driven by the wall follower on
the scan (agents.follow.edge.wall_beside / edge_step), at the wall follower's distance whatever
the pose estimate's error; lanes away from walls, and robots near peers, stay with DWA."""

from __future__ import annotations

import math

import numpy as np
from robots import ROBOT

from agents.control import scan_points
from agents.follow.edge import wall_beside
from agents.follow.motion import follow_step
from agents.follow.state import FollowParams, FollowState, Situation
from agents.time_use import step_kind
from fleet.params import AgentParams
from planners.dwa import DWAParams, rollout
from planners.wall_follow import WallFollowParams
from sim_server.lidar import add_noise, cast_scans

AGENT = AgentParams()
DWA = DWAParams()
WALL = WallFollowParams()
DT = 0.1
PARAMS = FollowParams(DWA, ROBOT, AGENT, WALL, DT)
BEAMS = 360
INCREMENT = 2 * math.pi / BEAMS
ANGLES = -math.pi + INCREMENT * np.arange(BEAMS)
# a wall along y = 0 under the lanes below, and one far above them
WALLS = np.array([[-1.0, 0.0, 5.0, 0.0], [-1.0, 2.0, 5.0, 2.0]])


def _drive(
    lane_y: float,
    seconds: float,
    pose_error: tuple[float, float] = (0.0, 0.0),
    peers: np.ndarray | None = None,
) -> tuple[np.ndarray, list[int], FollowState]:
    """The true (x, y) of a robot following a 3 m lane at ``lane_y`` with the edge pass on, its
    pose estimate off by ``pose_error``; and the follower's wall side at each step."""
    rng = np.random.default_rng(0)
    state = FollowState(np.array([[0.0, lane_y], [3.0, lane_y]]), index=1)
    pose, velocity = (0.0, lane_y, 0.0), (0.0, 0.0)
    peers = np.zeros((0, 2)) if peers is None else peers
    xy, sides = [], []
    for _ in range(round(seconds / DT)):
        ranges = cast_scans(
            np.array([pose[:2]]), np.array([pose[2]]), ANGLES, WALLS, np.zeros((0, 3)), 6.0
        )[0]
        ranges = add_noise(ranges, 0.01, 0.1, 6.0, rng)
        seen = (pose[0] + pose_error[0], pose[1] + pose_error[1], pose[2])
        obstacles = scan_points(seen, ranges, -math.pi, INCREMENT)
        before = state
        state, result = follow_step(state, Situation(seen, velocity, obstacles, peers), PARAMS)
        if result is None:
            break
        sides.append(state.edge_side)
        if state.edge_side:
            assert step_kind(before, state, 0) == "edge"
        velocity = (result.v, result.w)
        xs, ys, ths = rollout(pose, np.array([result.v]), np.array([result.w]), np.array([DT]))
        pose = (float(xs[0, 0]), float(ys[0, 0]), float(ths[0, 0]))
        xy.append(pose[:2])
    return np.array(xy), sides, state


def test_a_lane_hugging_a_wall_is_driven_at_the_wall_followers_distance() -> None:
    lane = WALL.distance + 0.04  # the plan's lane, 4 cm farther out than the follower holds
    xy, sides, state = _drive(lane, 30.0)
    assert state.done
    assert sides.count(-1) > 0.8 * len(sides)  # the wall is on the robot's right
    beside = xy[(xy[:, 0] > 0.8) & (xy[:, 0] < 2.7), 1]
    assert np.abs(beside - WALL.distance).max() <= 0.03
    assert beside.mean() < lane - 0.02  # closer to the wall than the lane: the band is swept


def test_the_wall_not_the_pose_estimate_sets_the_distance() -> None:
    """The estimate is 3 cm off toward the wall; DWA on the lane would hold the robot 3 cm
    farther out than planned, the wall follower holds it where the scan puts the wall."""
    xy, sides, _ = _drive(WALL.distance, 30.0, pose_error=(0.0, -0.03))
    beside = xy[(xy[:, 0] > 0.8) & (xy[:, 0] < 2.7), 1]
    assert sides.count(-1) > 0.8 * len(sides)
    assert np.abs(beside - WALL.distance).max() <= 0.03
    assert abs(beside.mean() - WALL.distance) < 0.01


def test_a_lane_away_from_walls_is_left_to_dwa() -> None:
    xy, sides, state = _drive(0.6, 30.0)
    assert state.done and not any(sides)
    assert np.abs(xy[xy[:, 0] > 0.8, 1] - 0.6).max() < 0.03


def test_a_peer_near_hands_the_lane_back_to_dwa() -> None:
    peer = np.array([[1.5, 0.8]])  # within edge_peer_clear of the whole lane's middle
    _, sides, _ = _drive(WALL.distance + 0.02, 6.0, peers=peer)
    assert not any(sides[-20:])


def test_wall_beside_needs_the_wall_along_the_stretch_ahead() -> None:
    """A wall that ends 0.1 m ahead of the robot (a doorway) is no wall to follow; one that
    runs on past the window is."""
    state = FollowState(np.array([[0.0, 0.2], [3.0, 0.2]]), index=1)
    pose = (1.0, 0.2, 0.0)
    running = np.array([[x, 0.0] for x in np.arange(0.0, 3.0, 0.01)])
    assert wall_beside(state, pose, running, WALL, AGENT) == -1
    ending = running[running[:, 0] < 1.1]
    assert wall_beside(state, pose, ending, WALL, AGENT) == 0
    assert wall_beside(state, pose, running + np.array([0.0, 0.4]), WALL, AGENT) == 1
    assert (
        wall_beside(state, pose, running - np.array([0.0, 0.15]), WALL, AGENT) == 0
    )  # too far out
