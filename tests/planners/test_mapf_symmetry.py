"""Corridor and rectangle reasoning (Li et al., AIJ 2021): the splits, and CBS / ECBS with them."""

from __future__ import annotations

import importlib
from collections.abc import Callable

import numpy as np
import pytest

from planners.mapf import MapfInstance, solve, validate
from planners.mapf.brute_force import brute_force_soc
from planners.mapf.cbs import CbsOptions
from planners.mapf.conflicts import positions
from planners.mapf.constraints import VERTEX
from planners.mapf.deadline import Deadline
from planners.mapf.grid_graph import GridGraph
from planners.mapf.mdd import mdd_blocks
from planners.mapf.model import InfeasibleInstanceError, check_instance
from planners.mapf.symmetry import corridor_branches, earliest_arrival, rectangle_branches
from planners.mapf.tables import ConstraintTable

WITH = CbsOptions(merge_threshold=0)
WITHOUT = CbsOptions(corridor=False, rectangle=False, merge_threshold=0)


def _ladder(width: int) -> np.ndarray:
    """Rows 0, 2 and 4 free, joined only by columns 0 and width - 1: row 2 between them is a
    one-lane corridor of width - 2 cells, rows 0 and 4 its bypasses."""
    free = np.zeros((5, width), dtype=bool)
    free[[0, 2, 4], :] = True
    free[:, [0, width - 1]] = True
    return free


def _row_path(graph: GridGraph, row: int, cols: range) -> list[int]:
    return [graph.cell((row, c)) for c in cols]


def test_a_head_on_meeting_in_a_corridor_splits_on_its_ends() -> None:
    graph = GridGraph(_ladder(9))
    a = _row_path(graph, 2, range(1, 8))  # (2, 1) → (2, 7)
    b = a[::-1]
    pos = positions([a, b])
    tables = (ConstraintTable(graph.num_cells), ConstraintTable(graph.num_cells))
    found = corridor_branches(graph, pos, (3, 0, 1, graph.cell((2, 4)), -1), tables, Deadline(5))
    assert found is not None
    # k = 6 between the starts; a reaches (2, 7) at 6 through the corridor, at 14 around it,
    # so it may not be there in [6, min(14 - 1, 6 + 6)] (and b at (2, 1) likewise)
    first, second = found
    assert first == tuple((VERTEX, 0, graph.cell((2, 7)), -1, t) for t in range(6, 13))
    assert second == tuple((VERTEX, 1, graph.cell((2, 1)), -1, t) for t in range(6, 13))
    # a swap in the corridor is the same corridor conflict
    swap = corridor_branches(
        graph, pos, (4, 0, 1, graph.cell((2, 4)), graph.cell((2, 3))), tables, Deadline(5)
    )
    assert swap == found


def test_a_swap_at_the_mouth_of_a_corridor_is_a_corridor_conflict() -> None:
    graph = GridGraph(_ladder(9))
    # a comes down column 0 and turns into the corridor at (2, 0) → (2, 1) while b, which
    # started inside at (2, 3), leaves it the other way: only (2, 1) has two neighbours
    a = [graph.cell(rc) for rc in ((0, 0), (1, 0))] + _row_path(graph, 2, range(0, 9))
    b = [*_row_path(graph, 2, range(3, -1, -1)), graph.cell((3, 0)), graph.cell((4, 0))]
    pos = positions([a, b])
    tables = (ConstraintTable(graph.num_cells), ConstraintTable(graph.num_cells))
    swap = (3, 0, 1, graph.cell((2, 0)), graph.cell((2, 1)))
    found = corridor_branches(graph, pos, swap, tables, Deadline(5))
    assert found is not None
    # corridor (2, 0)..(2, 3), k = 3: a reaches (2, 3) at 5 (around: later than b's 3 + 3 + 1),
    # b reaches (2, 0) at 3 (around: later than a's 5 + 3 + 1)
    first, second = found
    assert first == tuple((VERTEX, 0, graph.cell((2, 3)), -1, t) for t in range(5, 7))
    assert second == tuple((VERTEX, 1, graph.cell((2, 0)), -1, t) for t in range(3, 9))


def test_no_corridor_conflict_in_an_open_area_or_one_way() -> None:
    graph = GridGraph(np.ones((3, 5), dtype=bool))
    a = _row_path(graph, 1, range(0, 5))
    pos = positions([a, a[::-1]])
    tables = (ConstraintTable(graph.num_cells), ConstraintTable(graph.num_cells))
    assert (
        corridor_branches(graph, pos, (2, 0, 1, graph.cell((1, 2)), -1), tables, Deadline(5))
        is None
    )
    ladder = GridGraph(_ladder(9))
    ahead = _row_path(ladder, 2, range(2, 8))
    behind = [ladder.cell((2, 1)), *ahead[:-1]]
    # following an agent the same way is no corridor conflict (both entered at the same end)
    pos = positions([behind, ahead])
    assert (
        corridor_branches(ladder, pos, (1, 0, 1, ladder.cell((2, 2)), -1), tables, Deadline(5))
        is None
    )


def test_the_earliest_arrival_avoids_a_banned_move_and_respects_the_bound() -> None:
    graph = GridGraph(_ladder(9))
    table = ConstraintTable(graph.num_cells)
    start, target = graph.cell((2, 1)), graph.cell((2, 7))
    assert earliest_arrival(graph, start, target, table, None, 99, Deadline(5)) == 6
    banned = (start, graph.cell((2, 2)))
    assert earliest_arrival(graph, start, target, table, banned, 99, Deadline(5)) == 14
    assert earliest_arrival(graph, start, target, table, banned, 10, Deadline(5)) == 10
    table.add_vertex(target, 6)
    assert earliest_arrival(graph, start, target, table, None, 99, Deadline(5)) == 7


def test_two_agents_crossing_an_open_area_split_on_two_barriers() -> None:
    graph = GridGraph(np.ones((8, 8), dtype=bool))
    # a from (3, 0) right along row 3, then down to (6, 7); b from (0, 3) down column 3, then
    # right to (7, 6): both at (3, 3) at t = 3
    a = _row_path(graph, 3, range(0, 8)) + [graph.cell((r, 7)) for r in range(4, 7)]
    b = [graph.cell((r, 3)) for r in range(0, 8)] + _row_path(graph, 7, range(4, 7))
    found = rectangle_branches(graph, positions([a, b]), 3, 0, 1, graph.cell((3, 3)))
    assert found is not None
    first, second = found
    # a (entering from the left) is barred from the right side of (3, 3)..(6, 6) at its
    # Manhattan times, b (from the top) from the bottom side
    assert first == tuple((VERTEX, 0, graph.cell((r, 6)), -1, r + 3) for r in range(3, 7))
    assert second == tuple((VERTEX, 1, graph.cell((6, c)), -1, 3 + c) for c in range(3, 7))


def test_no_rectangle_when_an_agent_left_its_start_late_or_they_move_apart() -> None:
    graph = GridGraph(np.ones((8, 8), dtype=bool))
    b = [graph.cell((r, 3)) for r in range(0, 8)]
    late = [graph.cell((3, 0)), *_row_path(graph, 3, range(0, 7))]  # waited once at its start
    assert rectangle_branches(graph, positions([late, b]), 4, 0, 1, graph.cell((3, 3))) is None
    left = _row_path(graph, 3, range(6, -1, -1))  # right to left, b top to bottom
    assert rectangle_branches(graph, positions([left, b]), 3, 0, 1, graph.cell((3, 3))) is None


def test_a_branch_raises_the_cost_only_if_every_optimal_path_breaks_it() -> None:
    row = GridGraph(np.ones((1, 3), dtype=bool))
    empty = ConstraintTable(row.num_cells)
    assert mdd_blocks(row, 0, 2, 2, empty, {(1, 1)})
    assert not mdd_blocks(row, 0, 2, 2, empty, {(1, 2)})
    assert mdd_blocks(row, 0, 2, 2, empty, {(2, 5)})  # the agent stays at its goal
    square = GridGraph(np.ones((2, 2), dtype=bool))
    # two ways from 0 to 3 (through 1 or 2): one forbidden vertex leaves the other
    assert not mdd_blocks(square, 0, 3, 2, ConstraintTable(4), {(1, 1)})
    assert mdd_blocks(square, 0, 3, 2, ConstraintTable(4), {(1, 1), (2, 1)})


def _nodes(instance: MapfInstance, options: CbsOptions) -> tuple[int | None, int]:
    result = solve(instance, "cbs", time_limit_s=10, cbs_options=options)
    assert result.status == "success", result.message
    assert validate(instance, result.solution.paths).valid
    return result.soc, result.expanded_high


def test_corridor_reasoning_settles_a_head_on_corridor_in_one_split() -> None:
    width = 11
    instance = MapfInstance(_ladder(width), ((2, 1), (2, width - 2)), ((2, width - 1), (2, 0)))
    optimum = brute_force_soc(instance)
    soc, nodes = _nodes(instance, WITH)
    assert soc == optimum == 24
    assert nodes <= 2
    soc, nodes = _nodes(instance, WITHOUT)
    assert soc == optimum
    assert nodes >= 20


def test_rectangle_reasoning_settles_a_crossing_in_one_split() -> None:
    instance = MapfInstance(np.ones((8, 8), dtype=bool), ((3, 0), (0, 3)), ((6, 7), (7, 6)))
    optimum = brute_force_soc(instance)
    soc, nodes = _nodes(instance, WITH)
    assert soc == optimum == 21
    assert nodes <= 2
    soc, nodes = _nodes(instance, WITHOUT)
    assert soc == optimum
    assert nodes >= 50


def _crowded(count: int) -> list[MapfInstance]:
    """Seeded instances of 3 agents on grids of 2..4 x 2..4 cells with 30 % obstacles, where
    one-lane stretches are common (instances without a solution included)."""
    out = []
    i = 0
    while len(out) < count:
        rng = np.random.default_rng([18, i])
        i += 1
        rows, cols = (int(x) for x in rng.integers(2, 5, size=2))
        free = rng.random((rows, cols)) > 0.3
        cells = [(int(r), int(c)) for r, c in np.argwhere(free)]
        if len(cells) < 5:
            continue
        starts = [cells[j] for j in rng.permutation(len(cells))[:3]]
        goals = [cells[j] for j in rng.permutation(len(cells))[:3]]
        instance = MapfInstance(free, tuple(starts), tuple(goals))
        try:
            check_instance(instance)
        except InfeasibleInstanceError:
            continue
        out.append(instance)
    return out


def _crossings(count: int) -> list[MapfInstance]:
    """Seeded instances of 4..7 x 4..7 cells with 10 % obstacles: one agent from the left side
    to the right side, one from the top to the bottom, starting at the same distance from the
    corner, so that their shortest paths collide unless one gives way."""
    out = []
    i = 0
    while len(out) < count:
        rng = np.random.default_rng([19, i])
        i += 1
        rows, cols = (int(x) for x in rng.integers(4, 8, size=2))
        free = rng.random((rows, cols)) > 0.1
        r = int(rng.integers(min(rows, cols) - 1))
        a = ((r, 0), (int(rng.integers(r, rows)), cols - 1))
        b = ((0, r), (rows - 1, int(rng.integers(r, cols))))
        for cell in (*a, *b):
            free[cell] = True
        instance = MapfInstance(free, (a[0], b[0]), (a[1], b[1]))
        try:
            check_instance(instance)
        except InfeasibleInstanceError:
            continue
        out.append(instance)
    return out


@pytest.mark.parametrize("solver", ["cbs", "ecbs"])
def test_symmetry_reasoning_keeps_cbs_optimal_and_ecbs_bounded(
    solver: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    module = importlib.import_module(f"planners.mapf.{solver}")
    used = {"corridor": 0, "rectangle": 0}

    def counting(name: str, find: Callable[..., object]) -> Callable[..., object]:
        def wrapped(*args: object) -> object:
            found = find(*args)
            used[name] += found is not None
            return found

        return wrapped

    monkeypatch.setattr(module, "corridor_branches", counting("corridor", corridor_branches))
    monkeypatch.setattr(module, "rectangle_branches", counting("rectangle", rectangle_branches))
    for instance in _crowded(40) + _crossings(40):
        optimum = brute_force_soc(instance)
        result = solve(instance, solver, w=1.5, time_limit_s=5)
        if optimum is None:
            assert result.status != "success"
            continue
        assert result.status == "success", result.message
        assert validate(instance, result.solution.paths).valid
        if solver == "cbs":
            assert result.soc == optimum
        else:
            assert result.lower_bound <= optimum <= result.soc <= 1.5 * optimum
    # the instances exercise the reasoning (counts at the time of writing: cbs 60 corridor and
    # 27 rectangle splits, ecbs 18 corridor splits)
    assert used["corridor"] >= 10
    if solver == "cbs":
        assert used["rectangle"] >= 10
