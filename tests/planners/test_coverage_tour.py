"""Task order by path cost, path-cost estimates, lane pieces, and fill-in passes as tour legs."""

import itertools

import numpy as np
from coverage_maps import boxed, furnished, grid_of, open_spots
from robots import ROBOT

from planners.coverage import CoverageParams, plan_coverage
from planners.coverage.geodesic import PathCosts
from planners.coverage.metrics import swath
from planners.coverage.tasks import SweepTask
from planners.coverage.tour import end_points, insert_run, path_of, plan_tour, task_ends
from planners.coverage.transit import Transit
from planners.grid import clearance


def _two_rooms():
    """Two 2.4 m × 2.4 m rooms side by side; the wall between them is open only at the top."""
    occ = boxed(50, 100)
    occ[:, 50] = True
    occ[38:48, 50] = False
    return grid_of(occ)


def _lane_tasks(grid):
    """Horizontal lanes 0.6 m apart in both rooms (robot-centre columns 5–45 and 55–94): the
    next lane of the same room is farther in a straight line than the lane across the wall."""
    tasks = []
    for row in (6.5, 18.5, 30.5):
        for c0, c1 in ((5, 45), (55, 94)):
            path = grid.cell_to_world(np.array([[row, c0], [row, c1]], dtype=float))
            tasks.append(SweepTask(1, 1, (path,), 0.0, 0.0))
    return tasks


def _driven_length(grid, reach, start, tasks, tour):
    transit = Transit(grid, reach)
    p, total = start, 0.0
    for t, o in tour:
        v = path_of(tasks[t], o)
        leg = transit.path(p, v[0])
        total += float(np.hypot(*np.diff(leg, axis=0).T).sum())
        total += float(np.hypot(*np.diff(v, axis=0).T).sum())
        p = v[-1]
    return total


def test_order_by_path_cost_beats_straight_line_order_through_a_wall():
    g = _two_rooms()
    reach = clearance(g) >= 0.17
    tasks = _lane_tasks(g)
    start = np.array([0.3, 0.3])
    pts = np.vstack([end_points(tasks), start])
    euclid = np.hypot(*(pts[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
    geo = PathCosts(g, reach).matrix(pts)
    # across the wall the estimate is the way round through the opening, not 0.5 m
    a = 1  # end of the first lane of the left room, at column 45
    b = 2  # start of the first lane of the right room, at column 55
    assert euclid[a, b] < 0.6 and geo[a, b] > 2.5
    n = len(pts) - 1
    ids = list(range(len(tasks)))
    by_path = plan_tour(ids, n, task_ends(tasks, geo))
    by_line = plan_tour(ids, n, task_ends(tasks, euclid))
    good = _driven_length(g, reach, start, tasks, by_path)
    bad = _driven_length(g, reach, start, tasks, by_line)
    assert good < 0.85 * bad
    # the left room is swept completely before the robot goes through the opening
    rooms = [0 if path_of(tasks[t], o)[0][0] < 2.5 else 1 for t, o in by_path]
    assert rooms == sorted(rooms)


def test_path_costs_are_symmetric_at_least_straight_line_and_extend_consistently():
    g = _two_rooms()
    reach = clearance(g) >= 0.17
    rng = np.random.default_rng(0)
    cells = np.argwhere(reach)
    pts = g.cell_to_world(cells[rng.choice(len(cells), 40, replace=False)])
    costs = PathCosts(g, reach)
    first = costs.matrix(pts[:20])
    both = costs.matrix(pts)
    # exactly: the tour's local search reads a hop's cost from either end
    assert (both == both.T).all()
    assert (both >= np.hypot(*(pts[:, None] - pts[None, :]).transpose(2, 0, 1)) - 1e-9).all()
    assert np.allclose(both[:20, :20], first)


def test_lane_pieces_sweep_exactly_what_the_whole_lane_sweeps():
    g = grid_of(boxed(10, 50))
    whole = np.array([[0.225, 0.25], [2.275, 0.25]])
    pieces = [np.array([[0.225, 0.25], [1.225, 0.25]]), np.array([[1.225, 0.25], [2.275, 0.25]])]
    cov_w, visits_w = swath(g, whole, 0.15)
    cov_p, visits_p = swath(g, np.vstack([pieces[0], pieces[1][1:]]), 0.15)
    assert (cov_p == cov_w).all() and (visits_p == visits_w).all()
    # the corridor's one lane (columns 4–45) in pieces of at most 0.5 m, driven end to end
    params = CoverageParams(max_lane_length=0.5, fill_in=False)
    plan = plan_coverage(g, [(0.225, 0.25)], params, ROBOT, wall_clearance=0.0)
    assert len(plan.tasks[0]) == 5
    assert plan.metrics.total.repetition == 0.0
    assert np.isclose(plan.metrics.total.path_length_m, 41 * 0.05)


def _l_room():
    """An L-shaped room: 4 m × 1.5 m along the bottom and 1.5 m × 3 m up the left side."""
    occ = boxed(90, 90)
    occ[31:, 31:] = True
    return grid_of(occ)


def _stubs(path: np.ndarray, away: float = 0.15, window: int = 8) -> int:
    """Out-and-back stubs: the path comes back to a point it left within ``window`` vertices,
    having gone more than ``away`` from it (so the way there and back is swept twice)."""
    n = 0
    for i in range(len(path) - 2):
        seg = path[i + 1 : i + window + 1]
        back = np.flatnonzero(np.hypot(*(seg - path[i]).T) < 1e-6)
        if len(back) and np.hypot(*(seg[: back[0]] - path[i]).T).max() > away:
            n += 1
    return n


def test_l_shaped_room_reaches_the_coverage_target_without_stubs():
    g = _l_room()
    plan = plan_coverage(g, [(0.5, 0.5)], CoverageParams(), ROBOT, wall_clearance=0.0)
    assert plan.metrics.total.coverage >= 0.995
    assert _stubs(plan.paths[0]) == 0
    transit = Transit(g, clearance(g) >= 0.17)
    for a, b in itertools.pairwise(plan.paths[0]):
        assert transit.clear(a, b)


def test_fill_in_passes_are_tour_legs_not_out_and_back_stubs():
    # the former fill-in left from the nearest path vertex and came back to it: 3 and 1 stubs
    for seed in (4, 5):
        g = furnished(seed)
        plan = plan_coverage(g, open_spots(g, 1), CoverageParams(), ROBOT, wall_clearance=0.0)
        assert plan.metrics.total.coverage >= 0.995
        assert _stubs(plan.paths[0]) == 0


def test_a_fill_in_chain_is_driven_without_doubling_back():
    from planners.coverage.fill_in import _untangle

    pts = np.array([[0.0, 0.0], [0.1, 0.0], [0.2, 0.0], [0.3, 0.0], [0.3, 0.1], [0.3, 0.2]])
    order = _untangle(pts, np.array([2, 1, 0, 3, 4, 5]))
    assert sorted(order.tolist()) == list(range(6))
    length = np.hypot(*np.diff(pts[order], axis=0).T).sum()
    assert abs(length - 0.5) < 1e-9


def test_room_tours_put_in_whole_keep_their_order():
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [5.0, 0.0], [6.0, 0.0]])
    tasks = [SweepTask(0, 0, (np.array([p, p + np.array([0.0, 0.5])]),), 0.1, 1.0) for p in pts]
    every = np.vstack([end_points(tasks), [[-1.0, 0.0]]])
    ends = task_ends(tasks, np.hypot(*(every[:, None] - every[None, :]).transpose(2, 0, 1)))
    tour = [(0, 0), (1, 0), (2, 0)]
    out = insert_run(tour, [(4, 0), (3, 1)], 10, ends)
    assert [t for t, _ in out[:3]] == [0, 1, 2]
    assert out[3:] in ([(4, 0), (3, 1)], [(3, 0), (4, 1)])


def test_batched_local_search_makes_the_moves_of_the_one_at_a_time_scan(monkeypatch):
    # 2-opt and Or-opt price _CHUNK consecutive moves at once; with one per batch they are the
    # plain scan (first improving i, best place for it). Both must give the same tour.
    from planners.coverage import tour

    rng = np.random.default_rng(7)
    for trial in range(6):
        n = int(rng.integers(20, 90))
        tasks = [
            SweepTask(1, 1, (rng.uniform(0, 8, (2, 2)), rng.uniform(0, 8, (2, 2))), 0.0, 0.0)
            for _ in range(n)
        ]
        pts = np.vstack([end_points(tasks), [[4.0, 4.0]]])
        cost = np.hypot(*(pts[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
        detour = rng.uniform(1.0, 1.5, cost.shape)  # like ways round walls, the same both ways
        cost *= (detour + detour.T) / 2
        tours = []
        for chunk in (1, 5, 32):
            monkeypatch.setattr(tour, "_CHUNK", chunk)
            ends = task_ends(tasks, cost)
            tours.append(plan_tour(list(range(n)), len(pts) - 1, ends, closed=trial % 2 == 1))
        assert tours[0] == tours[1] == tours[2]
        assert len({t for t, _ in tours[0]}) == n
        # and the tour is a local optimum: no reversal and no moved run of 1-3 tasks is cheaper
        seq = [int(ends.offset[t] + o) for t, o in tours[0]]
        best = tour._total(np.array(seq), len(pts) - 1, ends)
        flip = [k ^ 1 for k in seq]
        for i, j in itertools.combinations_with_replacement(range(n), 2):
            other = seq[:i] + flip[i : j + 1][::-1] + seq[j + 1 :]
            assert tour._total(np.array(other), len(pts) - 1, ends) > best - 1e-9
        for length in (1, 2, 3):
            for i in range(n - length + 1):
                run, rest = seq[i : i + length], seq[:i] + seq[i + length :]
                for r in (run, [k ^ 1 for k in run][::-1]):
                    for p in range(len(rest) + 1):
                        other = np.array(rest[:p] + r + rest[p:])
                        assert tour._total(other, len(pts) - 1, ends) > best - 1e-9
