"""Polyline helpers shared by the planners."""

from __future__ import annotations

import itertools

import numpy as np
from robots import ROBOT

from planners.polyline import (
    LINE_M,
    LINE_TOLERANCE_M,
    TurnCounter,
    count_turns,
    heading_changes,
    path_length,
    simplify,
    simplify_indices,
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


def _off(path: np.ndarray, kept: np.ndarray) -> float:
    """How far the dropped points of ``path`` lie from the simplified path (its chords)."""
    simple = path[kept]
    worst = 0.0
    for a, b in itertools.pairwise(range(len(kept))):
        p, q = simple[a], simple[b]
        for x in path[kept[a] + 1 : kept[b]]:
            ab = q - p
            t = np.clip((x - p) @ ab / (ab @ ab), 0, 1)
            worst = max(worst, float(np.hypot(*(x - (p + t * ab)))))
    return worst


def test_a_line_the_plan_means_stays_on_its_line() -> None:
    """Three ways a 3 cm RDP moved the home tour's lines toward what they pass, as the
    tracker drove them (the tracker refused the nearer path, and DWA drove 92 s of the tour):
    a lane whose start lies 2.5 cm off the chord that skips it (the bed's foot), a hop that
    bends 15° round a door jamb 1.8 cm off its chord, and a lane laid in pieces 1.25 cm apart
    with a 5 cm piece between them (beside the sofa)."""
    bed = np.array(
        [[1.8875, 6.2375], [1.8875, 4.3625], [1.8375, 4.2625], [1.7375, 4.2375], [0.2375, 4.2375]]
    )
    jamb = np.array([[5.7375, 1.1125], [5.7875, 1.2125], [5.8834, 1.2375], [6.1375, 1.2375]])
    sofa = np.array([[2.3625, 1.0875], [1.8625, 1.1], [1.8125, 1.1], [0.2375, 1.0875]])
    for path in (bed, jamb, sofa):
        assert _off(path, simplify_indices(path, 0.03)) > 0.01  # what plain RDP did
        assert _off(path, simplify_indices(path, 0.03, LINE_M)) <= LINE_TOLERANCE_M


def test_grid_steps_beside_long_runs_are_still_absorbed() -> None:
    """A staircase's runs may be long (a wall 4° off the axes: 35 cm runs of 2.5 cm steps),
    and a diagonal step is one cell's diagonal: the steps still go."""
    for step in ([0.0, 0.025], [0.025, 0.025]):
        pts = [[0.0, 0.0]]
        for _ in range(4):
            x, y = pts[-1]
            pts += [[x + 0.35, y], [x + 0.35 + step[0], y + step[1]]]
        path = np.array(pts)
        assert simplify_indices(path, 0.03, LINE_M).tolist() == [0, len(path) - 1]
