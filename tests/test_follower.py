"""The agent's pure path-following step: reaching waypoints, turning in place, stopping at
corners, and tracking a boustrophedon path closely on a kinematic robot."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.follower import (
    FollowState,
    advance,
    back_up,
    control_step,
    rotate_in_place,
    stop_speed,
)
from fleet.params import AgentParams
from planners.dwa import DWAParams, rollout

AGENT = AgentParams()
DWA = DWAParams()
DT = 0.1


def test_lane_end_is_reached_along_the_lane_not_within_a_radius() -> None:
    lane = FollowState(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 0.3]]), index=1)
    assert advance(lane, np.array([1.9, 0.05]), AGENT).index == 1  # 0.1 m short: not yet
    assert advance(lane, np.array([1.98, 0.1]), AGENT).index == 2  # at the end, 0.1 m beside
    assert advance(lane, np.array([2.05, -0.02]), AGENT).index == 2  # past it
    assert advance(lane, np.array([1.99, 0.4]), AGENT).index == 1  # too far beside the lane


def test_rotate_in_place_brakes_and_turns_within_the_limits() -> None:
    v, w = rotate_in_place(2.0, (0.3, 0.0), DWA, DT)
    assert v == pytest.approx(0.3 - DWA.acc_lim_x * DT)
    assert w == pytest.approx(DWA.acc_lim_theta * DT)
    v, w = rotate_in_place(-2.0, (0.0, -1.0), DWA, DT)
    assert (v, w) == (0.0, -DWA.max_vel_theta)
    # close to the heading the rate is the one it can still stop from: sqrt(2·a·|error|)
    _, w = rotate_in_place(0.02, (0.0, 0.25), DWA, DT)
    assert w == pytest.approx(math.sqrt(2 * DWA.acc_lim_theta * 0.02))


def test_stop_speed_only_on_the_approach_to_a_sharp_corner() -> None:
    corner = FollowState(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 0.3]]), index=1)
    assert stop_speed(corner, np.array([0.5, 0.0]), DWA, 0.03) is None  # beyond braking distance
    v = stop_speed(corner, np.array([1.9, 0.0]), DWA, 0.03)
    assert v == pytest.approx(math.sqrt(2 * DWA.acc_lim_x * (0.1 - 0.015)))
    gentle = FollowState(np.array([[0.0, 0.0], [2.0, 0.0], [3.0, 1.0]]), index=1)  # 45°
    assert stop_speed(gentle, np.array([1.9, 0.0]), DWA, 0.03) is None


def _track(path: np.ndarray, pose: tuple[float, float, float], seconds: float):
    """Close the loop on an ideal unicycle (commands applied exactly for one period)."""
    state, velocity = FollowState(path), (0.0, 0.0)
    poses = [pose]
    for _ in range(round(seconds / DT)):
        state, result = control_step(state, pose, velocity, np.zeros((0, 2)), DWA, 0.17, DT, AGENT)
        if result is None:
            return poses, state, True
        velocity = (result.v, result.w)
        xs, ys, ths = rollout(pose, np.array([result.v]), np.array([result.w]), np.array([DT]))
        pose = (float(xs[0, 0]), float(ys[0, 0]), float(ths[0, 0]))
        poses.append(pose)
    return poses, state, False


def test_boustrophedon_is_tracked_to_centimetres_with_square_lane_ends() -> None:
    lanes = [0.0, 0.3, 0.6, 0.9]
    path = [[0.0, 0.0]]
    for k, y in enumerate(lanes):
        ends = [[0.0, y], [3.0, y]] if k % 2 == 0 else [[3.0, y], [0.0, y]]
        path += ends
    path = np.array(path[1:])
    # starts facing away from the first lane
    poses, state, finished = _track(path, (0.0, 0.0, math.pi), 120.0)
    assert finished and state.done
    xy = np.array([p[:2] for p in poses])
    on_lanes = (xy[:, 0] > 0.3) & (xy[:, 0] < 2.7)
    off = np.min(np.abs(xy[on_lanes, 1][:, None] - np.array(lanes)[None, :]), axis=1)
    assert off.max() < 0.03
    # every lane is driven to within a few centimetres of both its ends
    for y in lanes:
        near = xy[np.abs(xy[:, 1] - y) < 0.05]
        assert near[:, 0].min() < AGENT.goal_tolerance and near[:, 0].max() > 2.96


def test_back_up_reverses_only_while_the_way_behind_is_clear() -> None:
    state = FollowState(np.array([[0.0, 0.0], [2.0, 0.0]]), index=1, backing_m=0.15)
    ahead = np.array([[0.35, y] for y in np.linspace(-0.5, 0.5, 21)])
    stepped = back_up(state, (0.0, 0.0, 0.0), (0.0, 0.0), ahead, DWA, 0.17, DT, AGENT)
    assert stepped is not None
    after, result = stepped
    assert result.v == pytest.approx(-DWA.acc_lim_x * DT) and result.w == 0.0
    assert after.backing_m == pytest.approx(0.15 - DWA.acc_lim_x * DT * DT)
    wall_behind = np.array([[-0.25, y] for y in np.linspace(-0.5, 0.5, 21)])
    assert back_up(state, (0.0, 0.0, 0.0), (0.0, 0.0), wall_behind, DWA, 0.17, DT, AGENT) is None


def test_a_robot_wedged_against_a_wall_backs_up_and_then_drives_on() -> None:
    # facing a wall 0.16 m ahead, the goal beyond it to the left: no forward move is admissible
    wall = np.array([[0.16, y] for y in np.linspace(-1.0, 1.0, 81)])
    path = np.array([[0.0, 0.0], [0.0, 1.0]])
    state, pose, velocity = FollowState(path, index=1), (0.0, 0.0, 1.2), (0.0, 0.0)
    commands = []
    for _ in range(40):
        state, result = control_step(state, pose, velocity, wall, DWA, 0.17, DT, AGENT)
        assert result is not None
        commands.append(result.v)
        velocity = (result.v, result.w)
        xs, ys, ths = rollout(pose, np.array([result.v]), np.array([result.w]), np.array([DT]))
        pose = (float(xs[0, 0]), float(ys[0, 0]), float(ths[0, 0]))
    assert min(commands) < 0  # it reversed
    assert pose[0] < -0.05 or pose[1] > 0.1  # and got away from the wall
