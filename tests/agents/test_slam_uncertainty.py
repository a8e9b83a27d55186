"""The SLAM's use of odometry uncertainty: the tracking prior weakens and the tracking window
widens for long steps, the loop-closure window grows with the drift since the last closure, a
far closure waits for a second one that agrees, and the pose graph solver handles a pose
nothing constrains yet."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.slam.loop_closure import Closure, LoopCloser
from agents.slam.motion import prior_penalties, tracking_window
from agents.slam.pose_graph import PoseGraph
from fleet.slam_params import SlamParams

PARAMS = SlamParams()


def test_prior_penalties_follow_the_motion_model():
    short = prior_penalties(PARAMS, np.array([0.03, 0.0, 0.01]))
    long = prior_penalties(PARAMS, np.array([1.0, 0.0, 0.5]))
    assert short == (PARAMS.translation_penalty, PARAMS.rotation_penalty)
    sigma_xy = PARAMS.motion_xy_per_m * 1.0 + PARAMS.motion_xy_floor
    sigma_theta = PARAMS.motion_theta_per_rad * 0.5 + PARAMS.motion_theta_per_m * 1.0
    assert long[0] == pytest.approx(PARAMS.prior_weight / sigma_xy**2)
    assert long[1] == pytest.approx(PARAMS.prior_weight / sigma_theta**2)
    assert long[0] < short[0] and long[1] < short[1]


def test_tracking_window_spans_the_steps_odometry_error_between_its_floor_and_cap():
    # a 10 Hz step of a robot at 0.3 m/s: its error is millimetres, the window its floor
    assert tracking_window(PARAMS, np.array([0.03, 0.0, 0.01])) == (
        PARAMS.search_window_min_xy,
        PARAMS.search_window_min_theta,
    )
    # a step of a log whose scans lie far apart: search_window_sigmas sigmas of its error
    step = np.array([0.5, 0.3, 0.4])
    sigma_xy = PARAMS.motion_xy_per_m * math.hypot(0.5, 0.3) + PARAMS.motion_xy_floor
    sigma_theta = PARAMS.motion_theta_per_rad * 0.4 + PARAMS.motion_theta_per_m * math.hypot(
        0.5, 0.3
    )
    xy, theta = tracking_window(PARAMS, step)
    assert xy == pytest.approx(PARAMS.search_window_sigmas * sigma_xy)
    assert theta == pytest.approx(PARAMS.search_window_sigmas * sigma_theta)
    assert PARAMS.search_window_min_xy < xy < PARAMS.search_window_xy
    assert PARAMS.search_window_min_theta < theta < PARAMS.search_window_theta
    # a longer one: the caps
    assert tracking_window(PARAMS, np.array([3.0, 0.0, 2.0])) == (
        PARAMS.search_window_xy,
        PARAMS.search_window_theta,
    )


def test_loop_window_grows_with_drift_up_to_its_cap_and_resets_on_a_closure():
    graph = PoseGraph()
    closer = LoopCloser(PARAMS, graph)
    assert closer.windows() == (PARAMS.loop_window_xy, PARAMS.loop_window_theta)
    widths = []
    for _ in range(400):
        closer.accumulate_drift(np.array([0.5, 0.0, 0.05]))
        widths.append(closer.windows())
    xy = [w[0] for w in widths]
    assert xy == sorted(xy) and xy[0] == PARAMS.loop_window_xy
    assert xy[-1] == PARAMS.loop_window_max_xy and widths[-1][1] == PARAMS.loop_window_max_theta
    assert PARAMS.loop_window_xy < xy[len(xy) // 8] < PARAMS.loop_window_max_xy
    graph.add_pose(np.zeros(3))
    graph.add_pose(np.zeros(3))
    closer.add(Closure(1, 0, np.zeros(3), np.zeros(3), 1))
    assert closer.windows() == (PARAMS.loop_window_xy, PARAMS.loop_window_theta)
    assert (closer.closures, closer.pending, graph.num_constraints) == (1, 1, 1)


def test_closures_agree_when_they_imply_the_same_rigid_correction():
    graph = PoseGraph()
    closer = LoopCloser(PARAMS, graph)
    for pose in ([0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [8.0, 1.0, 0.3]):
        graph.add_pose(np.array(pose))
    shift = np.array([0.5, -0.8, 0.1])  # the trajectory is off by this rigid motion
    other = np.array([0.5, -0.2, 0.1])
    far_turn = np.array([0.5, -0.8, 0.2])
    first = Closure(1, 0, np.zeros(3), shift, 1)
    assert closer.agrees(first, Closure(2, 0, np.zeros(3), shift.copy(), 2))
    assert not closer.agrees(first, Closure(2, 0, np.zeros(3), other, 2))
    assert not closer.agrees(first, Closure(2, 0, np.zeros(3), far_turn, 2))


def test_gauss_newton_leaves_an_unconstrained_pose_and_solves_the_rest():
    graph = PoseGraph()
    graph.add_pose(np.zeros(3))
    graph.add_pose(np.array([1.2, 0.1, 0.05]))
    graph.add_pose(np.array([5.0, 5.0, 1.0]))  # a submap just started: no constraint yet
    graph.add_constraint(0, 1, np.array([1.0, 0.0, 0.0]), 0.05, 0.05)
    report = graph.optimize(huber_scale=1.0)
    assert np.allclose(graph.poses[1], [1.0, 0.0, 0.0], atol=1e-6)
    assert np.allclose(graph.poses[2], [5.0, 5.0, 1.0])
    assert report.final_cost < report.initial_cost and math.isfinite(report.final_cost)
