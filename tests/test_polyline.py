"""Polyline helpers shared by the planners."""

from __future__ import annotations

import numpy as np

from planners.polyline import heading_changes, path_length, without_straight_vertices


def test_straight_runs_become_one_segment_and_turns_stay() -> None:
    path = np.array([[0, 0], [0.1, 0], [0.25, 0], [0.25, 0], [1, 0], [1, 0.3], [0.5, 0.3]])
    out = without_straight_vertices(path)
    assert np.array_equal(out, [[0, 0], [1, 0], [1, 0.3], [0.5, 0.3]])
    assert path_length(out) == path_length(path)


def test_a_path_that_turns_back_keeps_its_tip() -> None:
    # an out-and-back stub: the tip lies on the line through its neighbours, but is a turn
    stub = np.array([[0, 0], [0.5, 0], [1, 0], [0.4, 0]])
    assert np.array_equal(without_straight_vertices(stub), [[0, 0], [1, 0], [0.4, 0]])


def test_short_paths_are_returned_whole() -> None:
    assert np.array_equal(without_straight_vertices(np.array([[1.0, 2.0]])), [[1.0, 2.0]])
    assert np.array_equal(without_straight_vertices(np.array([[0, 0], [0, 0]])), [[0, 0]])


def test_the_coverage_plan_drives_no_straight_vertices() -> None:
    from fleet.config import resolve_world
    from fleet.params import load_fleet_config
    from fleet.world import load_world
    from planners.coverage import CoverageParams, plan_coverage

    cfg = load_fleet_config()
    world = load_world(resolve_world("small"), cfg.robot.radius)
    starts = [p[:2] for p in world.start_poses(1, cfg.robot.radius)]
    plan = plan_coverage(world.grid(0.05), starts, CoverageParams())
    path = plan.paths[0]
    assert (np.hypot(*np.diff(path, axis=0).T) > 1e-9).all()
    assert (heading_changes(path) > 1e-6).all()
