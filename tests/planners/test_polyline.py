"""Polyline helpers shared by the planners."""

from __future__ import annotations

import itertools

import numpy as np
from robots import ROBOT

from planners.polyline import (
    TurnCounter,
    count_turns,
    heading_changes,
    path_length,
    simplify,
    without_straight_vertices,
)


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
    plan = plan_coverage(world.grid(0.05), starts, CoverageParams(), ROBOT, wall_clearance=0.0)
    path = plan.paths[0]
    assert (np.hypot(*np.diff(path, axis=0).T) > 1e-9).all()
    assert (heading_changes(path) > 1e-6).all()


def _counted_as_it_grows(points: np.ndarray, every: int) -> list[tuple[int, int]]:
    """(points so far, turns) from a TurnCounter counted every ``every`` points, and from
    simplifying the same prefix from scratch."""
    counter = TurnCounter(0.05)
    pairs = []
    for k, (x, y) in enumerate(points.tolist(), start=1):
        counter.append(x, y)
        if k % every == 0 or k == len(points):
            scratch = count_turns(simplify(points[:k], 0.05))
            pairs.append((counter.turns(), scratch))
    return pairs


def test_turns_counted_as_a_path_grows_equal_a_count_from_scratch() -> None:
    rng = np.random.default_rng(3)
    # A wandering drive (slowly varying curvature, sampled every 5 cm), a lawnmower with
    # repeated points at its corners and a square spiral (its simplification nests as deep as
    # it has corners): all with many turns at 0.05 m tolerance.
    heading = np.cumsum(rng.normal(0, 0.25, 1500))
    wander = np.cumsum(0.05 * np.column_stack([np.cos(heading), np.sin(heading)]), axis=0)
    lanes = [[[0, y], [3, y], [3, y], [3, y + 0.3]] for y in np.arange(0, 3, 0.6)]
    mower = np.array([p for lane in lanes for p in lane], dtype=float)
    mower = np.vstack([np.linspace(a, b, 12) for a, b in itertools.pairwise(mower)])
    steps = [[(1, 0), (0, 1), (-1, 0), (0, -1)][k % 4] for k in range(40) for _ in range(k + 1)]
    spiral = np.cumsum(0.05 * np.array(steps, dtype=float), axis=0)
    for points, every in ((wander, 7), (wander, 1), (mower, 3), (spiral, 5)):
        pairs = _counted_as_it_grows(points, every)
        assert [a for a, _ in pairs] == [b for _, b in pairs]
        assert pairs[-1][1] > 10


def test_turn_counter_of_short_paths() -> None:
    counter = TurnCounter(0.05)
    assert counter.turns() == 0
    counter.append(1.0, 1.0)
    counter.append(1.0, 1.0)
    assert counter.turns() == 0 and len(counter) == 2
    counter.append(2.0, 1.0)
    counter.append(2.0, 2.0)
    assert counter.turns() == 1
    np.testing.assert_array_equal(counter.points(), [[1, 1], [1, 1], [2, 1], [2, 2]])


def _stretch_reference(points: np.ndarray, stretch: int) -> int:
    """Turns of the path simplified in stretches of ``stretch`` points sharing their ends."""
    step = stretch - 1
    parts = [
        simplify(points[k : k + stretch], 0.05)[(1 if k else 0) :]
        for k in range(0, len(points) - 1, step)
    ]
    return count_turns(np.vstack(parts))


def test_turns_in_stretches_equal_the_stretches_simplified_apart_and_memory_stays_bounded():
    rng = np.random.default_rng(5)
    heading = np.cumsum(rng.normal(0, 0.25, 6000))
    wander = np.cumsum(0.05 * np.column_stack([np.cos(heading), np.sin(heading)]), axis=0)
    counter = TurnCounter(0.05, stretch_points=500)
    largest_memo = largest_buffer = 0
    for k, (x, y) in enumerate(wander.tolist(), start=1):
        counter.append(x, y)
        if k % 50 == 0 or k == len(wander):
            assert counter.turns() == _stretch_reference(wander[:k], 500)
            largest_memo = max(largest_memo, len(counter._memo))
            largest_buffer = max(largest_buffer, len(counter._pts))
    assert len(counter) == len(wander) and len(counter.points()) <= 500
    assert largest_buffer <= 512 and largest_memo <= 2 * 500
    whole = count_turns(simplify(wander, 0.05))
    assert abs(counter.turns() - whole) <= len(wander) // 499 + 1
