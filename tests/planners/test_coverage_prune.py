"""Dropping tasks whose floor the rest of the driven path cleans, transits included."""

import numpy as np
from coverage_maps import boxed, grid_of

from planners.coverage.metrics import swath
from planners.coverage.prune import Footprints, prune_driven
from planners.coverage.tasks import SweepTask
from planners.coverage.transit import Transit
from planners.grid import cleanable, clearance, reachable


def _task(a, b) -> SweepTask:
    return SweepTask(0, 1, (np.array([a, b], dtype=float),), 0.0, 0.0)


def _setup():
    g = grid_of(boxed(60, 90))
    centres = clearance(g) >= 0.17
    reach = reachable(centres, g.world_to_cell(np.array([[0.5, 1.0]])))
    return g, reach, cleanable(g, reach, 0.15), Transit(g, reach)


def test_a_lane_piece_on_the_way_to_the_next_task_is_dropped_and_no_floor_is_lost():
    g, _, clean, transit = _setup()
    start = np.array([[0.5, 1.0]])
    # the hop from the start to the far lane, once straight, sweeps the short piece's floor
    # (half a cell off its line) ...
    on_the_way = _task((1.0, 1.025), (1.5, 1.025))
    # ... but not over this one, which only it sweeps
    aside = _task((3.0, 2.0), (3.5, 2.0))
    far = _task((3.0, 1.0), (3.5, 1.0))
    tasks = [on_the_way, far, aside]
    tour = [[(0, 0), (1, 0), (2, 0)]]
    _, kept = prune_driven(tasks, tour, start, Footprints(g, clean, 0.15), transit)
    assert kept == [[(1, 0), (2, 0)]]

    def driven(steps):
        pts = [start[0]]
        for t, _ in steps:
            pts.extend(tasks[t].variants[0])
        return np.array(pts)

    before, _ = swath(g, driven(tour[0]), 0.15)
    after, _ = swath(g, driven(kept[0]), 0.15)
    assert not (before & ~after & clean).any()


def test_the_last_task_stays_when_nothing_else_passes_over_it():
    g, _, clean, transit = _setup()
    start = np.array([[0.5, 1.0]])
    tasks = [_task((1.0, 1.0), (1.5, 1.0)), _task((1.0, 2.0), (1.5, 2.0))]
    tour = [[(0, 0), (1, 0)]]
    assert prune_driven(tasks, tour, start, Footprints(g, clean, 0.15), transit)[1] == tour


def _driven(transit, start, tasks, steps):
    pts = [start[0][None, :]]
    for t, _ in steps:
        v = tasks[t].variants[0]
        pts.append(transit.path(pts[-1][-1], v[0])[1:])
        pts.append(v)
    return np.vstack(pts)


def test_with_a_coverage_floor_the_costliest_cells_go_first_and_the_floor_holds():
    g, _, clean, transit = _setup()
    start = np.array([[0.5, 1.0]])
    # two lanes along the room, and a short piece across its far end, a detour for few cells
    tasks = [
        _task((0.5, 1.0), (4.0, 1.0)),
        _task((4.0, 1.3), (0.5, 1.3)),
        _task((0.5, 2.6), (0.7, 2.6)),
    ]
    tour = [[(0, 0), (1, 0), (2, 0)]]
    full, _ = swath(g, _driven(transit, start, tasks, tour[0]), 0.15)
    without, _ = swath(g, _driven(transit, start, tasks, tour[0][:2]), 0.15)
    n_full, n_without = int((full & clean).sum()), int((without & clean).sum())
    assert n_without < n_full
    prints = Footprints(g, clean, 0.15)
    # the floor allows losing exactly the piece's own cells: it goes, the lanes stay (their
    # ends may be shortened where that loses nothing)
    out, kept = prune_driven(tasks, tour, start, prints, transit, min_cells=n_without)
    assert sorted(out[t].variants[0][0][1] for t, _ in kept[0]) == [1.0, 1.3]
    after, _ = swath(g, _driven(transit, start, out, kept[0]), 0.15)
    assert int((after & clean).sum()) >= n_without
    # with every cell to keep, no task may go
    out, kept = prune_driven(tasks, tour, start, prints, transit, min_cells=n_full)
    assert len(kept[0]) == 3
    after, _ = swath(g, _driven(transit, start, out, kept[0]), 0.15)
    assert int((after & clean).sum()) >= n_full


def test_a_lane_end_another_lane_sweeps_is_cut_back_and_no_floor_is_lost():
    g, _, clean, transit = _setup()
    start = np.array([[0.5, 1.0]])
    # the first lane runs into the second one, which crosses its end
    tasks = [_task((0.5, 1.0), (4.0, 1.0)), _task((4.0, 0.5), (4.0, 2.5))]
    tour = [[(0, 0), (1, 0)]]
    out, kept = prune_driven(tasks, tour, start, Footprints(g, clean, 0.15), transit)
    (first, _), (second, _) = kept[0]
    assert first == 2 and second == 1
    lane = out[first].variants[0]
    assert lane[0].tolist() == [0.5, 1.0] and 3.7 <= lane[1][0] < 4.0 and lane[1][1] == 1.0
    before, _ = swath(g, _driven(transit, start, tasks, tour[0]), 0.15)
    after, _ = swath(g, _driven(transit, start, out, kept[0]), 0.15)
    assert not (before & ~after & clean).any()


def test_a_path_is_cut_back_along_its_segments():
    from planners.polyline import cut_start

    bent = np.array([[0.0, 0.0], [0.2, 0.0], [0.2, 1.0]])
    assert np.allclose(cut_start(bent, 0.3), [[0.2, 0.1], [0.2, 1.0]])
    assert np.allclose(cut_start(bent, 0.1), [[0.1, 0.0], [0.2, 0.0], [0.2, 1.0]])
    assert np.allclose(cut_start(bent[::-1], 0.5)[::-1], [[0.0, 0.0], [0.2, 0.0], [0.2, 0.5]])
