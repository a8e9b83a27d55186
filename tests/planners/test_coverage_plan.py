"""plan_coverage: analytic cases, safety of every path, decomposition invariants, splitting."""

import itertools
import math

import numpy as np
import pytest
from coverage_maps import DATA, RES, boxed, furnished, grid_of, open_spots
from robots import ROBOT

from planners.coverage import CoverageParams, PlanningError, plan_coverage
from planners.coverage.bcd import decompose
from planners.coverage.rooms import shared_borders

PARAMS = CoverageParams()
SWEEPS_ONLY = CoverageParams(fill_in=False)


def test_corridor_one_lane_matches_the_analytic_values():
    # walls at rows 0 and 9, columns 0 and 49: robot centres fit on rows 4–5, columns 4–45
    g = grid_of(boxed(10, 50))
    start = ((4 + 0.5) * RES, 5 * RES)  # on the lane between rows 4 and 5, at its first column
    plan = plan_coverage(g, [start], SWEEPS_ONLY, ROBOT, wall_clearance=0.0)
    m = plan.metrics.total
    assert math.isclose(m.path_length_m, 41 * RES, abs_tol=1e-9)
    assert m.turns == 0 and m.repetition == 0.0
    # cleanable: rows 2–7 × columns 2–47 = 276 cells; the swath's round ends miss the two
    # cells at (row ± 2.5, column ± 2) beyond each end of the lane
    assert math.isclose(plan.metrics.cleanable_area_m2, 276 * RES**2)
    assert math.isclose(m.coverage, 272 / 276)


def test_empty_rectangle_lanes_length_and_coverage():
    g = grid_of(boxed(40, 60))  # robot centres: rows 4–35, columns 4–55
    start = (4.5 * RES, 5 * RES)
    plan = plan_coverage(g, [start], SWEEPS_ONLY, ROBOT, wall_clearance=0.0)
    m = plan.metrics.total
    # 6 lanes 51 cells long (rows 4.5, 10.5, …, 34.5) and 5 turns of 6 rows along the sides
    assert math.isclose(m.path_length_m, (6 * 51 + 5 * 6) * RES, abs_tol=1e-9)
    assert m.turns == 10
    assert m.coverage >= 0.99
    # every covered cell is cleaned once except two per turn: the cells 2.5 rows off the lane
    # and 2 columns before the turn, √(2² + 2.5²) > 3 cells from the corner, leave the brush
    # along the lane and enter it again on the turn: 10 extra visits
    covered = round(m.covered_area_m2 / RES**2)
    assert math.isclose(m.repetition, (covered + 10) / covered - 1)


def _crossings(grid, path):
    pts = [path[:1]]
    for a, b in itertools.pairwise(path):
        n = max(2, int(np.ceil(np.hypot(*(b - a)) / (grid.resolution / 4))) + 1)
        pts.append(a + (b - a) * np.linspace(0, 1, n)[:, None])
    rc = grid.world_to_cell(np.vstack(pts))
    assert grid.in_bounds(rc).all()
    return int((grid.occupied | grid.unknown)[rc[:, 0], rc[:, 1]].sum())


def _maps():
    from fleet.world import load_world

    for seed in (0, 1):
        g = furnished(seed)
        yield f"furnished{seed}", g, open_spots(g, 3)
    for name in ("home", "small"):
        w = load_world(f"configs/worlds/{name}.yaml")
        yield name, w.grid(RES), [p[:2] for p in w.start_poses(3, 0.17)]


def test_no_path_crosses_an_occupied_or_unknown_cell():
    params = CoverageParams()
    for name, g, starts in _maps():
        for k in (1, 3):
            plan = plan_coverage(g, starts[:k], params, ROBOT, wall_clearance=0.0)
            for path in plan.paths:
                assert _crossings(g, path) == 0, (name, k)
            assert plan.metrics.total.coverage > 0.95, (name, k)


def test_apartment_paths_are_safe_and_cover_it():
    path = DATA / "cob_ipa_apartment.yaml"
    if not path.exists():
        pytest.skip(f"{path} is absent (shared data not checked out)")
    from fleet.world import load_world

    w = load_world(path)
    g = w.grid(RES)
    plan = plan_coverage(
        g, [p[:2] for p in w.start_poses(3, 0.17)], PARAMS, ROBOT, wall_clearance=0.0
    )
    assert all(_crossings(g, p) == 0 for p in plan.paths)
    assert plan.metrics.total.coverage > 0.97
    assert plan.room_labels.max() >= 5


def test_decomposition_cells_are_disjoint_cover_the_cleanable_area_and_adjacency_is_symmetric():
    for g in (furnished(2), furnished(3)):
        plan = plan_coverage(g, open_spots(g, 1), PARAMS, ROBOT, wall_clearance=0.0)
        labels = plan.cell_labels
        assert np.array_equal(labels > 0, plan.cleanable)
        assert set(plan.cell_graph.nodes) == set(np.unique(labels[labels > 0]).tolist())
        borders = shared_borders(labels)
        assert set(borders) == {tuple(sorted(e)) for e in plan.cell_graph.edges}
        for a, b in plan.cell_graph.edges:
            assert plan.cell_graph.has_edge(b, a)
        rooms = plan.room_labels
        assert np.array_equal(rooms > 0, plan.cleanable)
        for a, b in plan.room_graph.edges:
            door = plan.room_graph.edges[a, b]["door"]
            assert plan.room_graph.has_edge(b, a) and len(door) == 2
        area = sum(nx_area for _, nx_area in plan.cell_graph.nodes(data="area_m2"))
        assert math.isclose(area, plan.metrics.cleanable_area_m2)


def test_bcd_cells_are_row_monotone_and_split_at_an_obstacle():
    mask = np.ones((30, 40), dtype=bool)
    mask[10:20, 15:25] = False
    labels, cells = decompose(mask)
    assert len(cells) == 4  # below, left, right, above the obstacle
    assert np.array_equal(labels > 0, mask)
    rng = np.random.default_rng(0)
    noisy = rng.random((40, 50)) > 0.2
    labels, cells = decompose(noisy)
    assert np.array_equal(labels > 0, noisy)
    for k, cell in enumerate(cells, start=1):
        rows = np.nonzero((labels == k).any(axis=1))[0]
        assert rows[0] == cell.row0 and len(rows) == cell.rows
        for i, r in enumerate(rows):
            cols = np.nonzero(labels[r] == k)[0]
            assert cols[0] == cell.left[i] and cols[-1] == cell.right[i]
            assert len(cols) == cols[-1] - cols[0] + 1


def test_three_robots_share_the_work():
    from fleet.world import load_world

    w = load_world("configs/worlds/home.yaml")
    g = w.grid(RES)
    starts = [p[:2] for p in w.start_poses(3, 0.17)]
    one = plan_coverage(g, starts[:1], PARAMS, ROBOT, wall_clearance=0.0)
    three = plan_coverage(g, starts, PARAMS, ROBOT, wall_clearance=0.0)
    assert three.metrics.makespan_s <= 0.45 * one.metrics.makespan_s
    assert three.metrics.total.coverage >= one.metrics.total.coverage - 0.01
    assert set(three.assignment.values()) == {0, 1, 2}
    for i, path in enumerate(three.paths):
        assert np.allclose(path[0], starts[i])


def test_bad_starts_and_maps_raise_clear_errors():
    g = grid_of(boxed(40, 60))
    with pytest.raises(PlanningError, match="inside an obstacle"):
        plan_coverage(g, [(0.02, 1.0)], PARAMS, ROBOT, wall_clearance=0.0)
    with pytest.raises(PlanningError, match="closer than the robot radius"):
        plan_coverage(g, [(0.1, 1.0)], PARAMS, ROBOT, wall_clearance=0.0)
    with pytest.raises(PlanningError, match="outside the map"):
        plan_coverage(g, [(10.0, 1.0)], PARAMS, ROBOT, wall_clearance=0.0)
    with pytest.raises(PlanningError, match="no free cell"):
        plan_coverage(
            grid_of(np.ones((10, 10), bool)), [(0.2, 0.2)], PARAMS, ROBOT, wall_clearance=0.0
        )
    with pytest.raises(ValueError, match="overlap"):
        plan_coverage(g, [(1.0, 1.0)], CoverageParams(overlap=1.5), ROBOT, wall_clearance=0.0)


def test_unreachable_free_space_is_reported():
    occ = boxed(40, 81)
    occ[:, 40] = True  # the right room has no door
    g = grid_of(occ)
    plan = plan_coverage(g, [(1.0, 1.0)], PARAMS, ROBOT, wall_clearance=0.0)
    right_room = 38 * 39 * RES**2
    assert plan.unreachable_area_m2 >= right_room
    assert plan.unreachable[20, 60] and not plan.cleanable[20, 60]
    assert plan.metrics.unreachable_free_m2 == pytest.approx(plan.unreachable_area_m2)
