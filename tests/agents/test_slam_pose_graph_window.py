"""The pose graph's optimization window: poses older than the window are held where they are,
the constraints between two held poses leave the graph, and a closure against a held pose
still pulls the newest poses onto it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.slam.geometry import compose, relative
from agents.slam.pose_graph import PoseGraph
from fleet.slam_params import SlamParams


def _drifting_loop(window: int, laps: int = 4, per_lap: int = 40) -> tuple[PoseGraph, np.ndarray]:
    """Laps round a 4 m circle: odometry edges that drift in heading, and a closure from the
    last pose of every lap to the first pose of the first lap."""
    n = laps * per_lap
    angles = 2 * math.pi * np.arange(n + 1) / per_lap
    true = np.stack([2 * np.sin(angles), 2 - 2 * np.cos(angles), angles], axis=1)
    graph = PoseGraph(window)
    pose = true[0].copy()
    graph.add_pose(pose)
    for i in range(1, n + 1):
        z = relative(true[i - 1], true[i]) + np.array([0.0, 0.0, 0.01])
        pose = compose(pose, z)
        graph.add_pose(pose)
        graph.add_constraint(i - 1, i, z, 0.05, 0.05)
        if i % per_lap == 0:
            graph.add_constraint(0, i, relative(true[0], true[i]), 0.01, 0.01)
            graph.optimize(huber_scale=10.0)
    return graph, true


def test_a_window_wider_than_the_graph_changes_nothing():
    whole, _ = _drifting_loop(window=0)
    wide, _ = _drifting_loop(window=10_000)
    np.testing.assert_allclose(wide.poses, whole.poses, atol=1e-12)
    assert wide.held == 0
    assert wide.num_constraints == whole.num_constraints


def test_old_poses_are_held_and_their_constraints_dropped():
    graph, _ = _drifting_loop(window=50)
    n = graph.poses.shape[0]
    assert graph.held == n - 50
    # only constraints reaching into the window stay: the odometry chain through it (49), the
    # edge that crosses into it, and the closures of the last two laps, whose ends are in it
    assert graph.num_constraints == 49 + 1 + 2
    held_before = graph.poses[: graph.held].copy()
    graph.add_constraint(n - 1, n - 1 - 20, np.zeros(3), 0.01, 0.01)
    graph.optimize(huber_scale=10.0)
    np.testing.assert_array_equal(graph.poses[: n - 50], held_before[: n - 50])


def test_a_closure_against_a_held_pose_pulls_the_newest_onto_it():
    graph, true = _drifting_loop(window=50)
    # every lap closed onto pose 0, which the window holds: the end of the last lap is on it
    assert np.hypot(*(graph.poses[-1, :2] - true[-1, :2])) < 0.05
    whole, _ = _drifting_loop(window=0)
    assert np.hypot(*(whole.poses[-1, :2] - true[-1, :2])) < 0.05


def test_a_negative_window_is_refused():
    with pytest.raises(ValueError, match="window"):
        PoseGraph(-1)


def test_the_config_field_is_checked_by_name():
    with pytest.raises(ValueError, match="optimize_window_nodes"):
        SlamParams(optimize_window_nodes=-1).validate()
