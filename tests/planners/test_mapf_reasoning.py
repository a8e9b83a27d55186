"""Target reasoning (length constraints) and the joint search of meta-agents, piece by piece."""

from __future__ import annotations

import numpy as np
import pytest

from planners.mapf import MapfInstance, solve, validate
from planners.mapf.brute_force import brute_force_soc
from planners.mapf.conflicts import positions
from planners.mapf.constraints import (
    LENGTH_GT,
    LENGTH_LE,
    TARGET,
    VERTEX,
    as_target,
    split,
    table_for,
    violators,
)
from planners.mapf.deadline import Deadline
from planners.mapf.grid_graph import GridGraph
from planners.mapf.joint import joint_astar
from planners.mapf.low_level import SearchStats, space_time_astar
from planners.mapf.mdd import mdd_singletons
from planners.mapf.model import path_cost
from planners.mapf.tables import ConstraintTable
from planners.mapf.tiny import tiny_case

ROW = GridGraph(np.ones((1, 3), dtype=bool))  # cells 0 - 1 - 2
DEAD_END = np.array([[1, 1, 1, 1], [1, 1, 0, 1], [1, 0, 1, 1], [0, 1, 1, 0]], dtype=bool)


def test_a_vertex_conflict_at_a_parked_agents_goal_is_a_target_conflict() -> None:
    goals, costs = [2, 1], [2, 0]
    # agent 0 passes agent 1's goal (cell 1) at t = 1, after agent 1 arrived (cost 0)
    assert as_target((1, 0, 1, 1, -1), goals, costs) == (1, 0, 1, 1, TARGET)
    # reported the other way round, the parked agent still ends up second
    assert as_target((1, 1, 0, 1, -1), goals, costs) == (1, 0, 1, 1, TARGET)
    # before the agent's arrival it is an ordinary vertex conflict
    assert as_target((1, 0, 1, 1, -1), goals, [2, 3]) == (1, 0, 1, 1, -1)


def test_a_target_conflict_splits_on_the_parked_agents_length() -> None:
    left, right = split((4, 0, 1, 7, TARGET))
    assert left == (LENGTH_GT, 1, 7, -1, 4)
    assert right == (LENGTH_LE, 1, 7, -1, 4)
    assert split((4, 0, 1, 7, -1)) == [(VERTEX, 0, 7, -1, 4), (VERTEX, 1, 7, -1, 4)]
    gt = table_for(9, [left], 1)
    assert gt.earliest_finish(7) == 5
    le = table_for(9, [right], 1)
    assert le.max_finish == 4
    assert le.earliest_finish(7) == 0
    # l_b ≤ t forbids every other agent in b's goal from t on
    for other in (0, 2):
        assert table_for(9, [right], other).blocked_from == {7: 4}


def test_the_length_le_child_replans_every_agent_in_the_goal_from_t_on() -> None:
    pos = positions([[0, 1, 2], [7], [3, 7, 3], [7, 8]])
    assert violators((LENGTH_LE, 1, 7, -1, 1), pos) == [2]
    assert violators((LENGTH_LE, 1, 7, -1, 2), pos) == []
    assert violators((LENGTH_LE, 0, 7, -1, 0), pos) == [1, 2, 3]
    assert violators((LENGTH_GT, 1, 7, -1, 2), pos) == [1]


def test_a_minimum_length_makes_the_agent_leave_its_goal_and_come_back() -> None:
    table = ConstraintTable(ROW.num_cells)
    table.add_min_finish(3)
    path = space_time_astar(ROW, 1, 1, table, None, Deadline(1), SearchStats())
    assert path is not None
    assert path_cost(path) == 3
    assert path[0] == path[-1] == 1


def test_a_maximum_length_below_the_distance_has_no_path() -> None:
    table = ConstraintTable(ROW.num_cells)
    table.add_max_finish(1)
    assert space_time_astar(ROW, 0, 2, table, None, Deadline(1), SearchStats()) is None
    table = ConstraintTable(ROW.num_cells)
    table.add_max_finish(2)
    table.add_vertex(1, 1)  # the only way is blocked at t = 1, and waiting makes it too late
    assert space_time_astar(ROW, 0, 2, table, None, Deadline(1), SearchStats()) is None


def test_the_mdd_of_a_forced_length_excludes_staying_on_the_goal() -> None:
    pair = GridGraph(np.ones((1, 2), dtype=bool))
    table = ConstraintTable(pair.num_cells)
    table.add_min_finish(2)
    # cost 2 from goal 0: the only path is 0 → 1 → 0 (0 → 0 → 0 has cost 0)
    assert mdd_singletons(pair, 0, 0, 2, table) == (0, 1, 0)


def _joint_soc(instance: MapfInstance, tables=None) -> int | None:
    graph = GridGraph(instance.free)
    k = instance.num_agents
    paths = joint_astar(
        graph,
        [graph.cell(s) for s in instance.starts],
        [graph.cell(g) for g in instance.goals],
        tables or [ConstraintTable(graph.num_cells) for _ in range(k)],
        None,
        Deadline(5),
        SearchStats(),
    )
    if paths is None:
        return None
    report = validate(instance, [[graph.rc(c) for c in p] for p in paths])
    assert report.valid, report.errors
    return report.soc


@pytest.mark.parametrize("index", range(12))
def test_the_joint_search_alone_agrees_with_the_brute_force(index: int) -> None:
    case = tiny_case(7, index)
    assert _joint_soc(case.instance) == case.optimum


def test_the_joint_search_solves_the_dead_end_and_proves_a_swap_impossible() -> None:
    instance = MapfInstance(DEAD_END, ((0, 1), (0, 0), (2, 3)), ((3, 2), (1, 3), (2, 2)))
    assert _joint_soc(instance) == 32
    corridor = np.ones((1, 4), dtype=bool)
    assert _joint_soc(MapfInstance(corridor, ((0, 0), (0, 3)), ((0, 3), (0, 0)))) is None


def test_the_joint_search_respects_its_members_constraints() -> None:
    pocket = np.array([[1, 1, 1, 1, 1], [0, 0, 1, 0, 0]], dtype=bool)
    instance = MapfInstance(pocket, ((0, 2), (0, 0)), ((0, 2), (0, 4)))
    assert _joint_soc(instance) == 7
    graph = GridGraph(pocket)
    late = ConstraintTable(graph.num_cells)
    late.add_min_finish(6)  # agent 0 may not be back on its goal for good before t = 6
    assert _joint_soc(instance, [late, ConstraintTable(graph.num_cells)]) == 6 + 4


@pytest.mark.parametrize("solver", ["cbs", "ecbs"])
def test_merged_agents_stay_optimal_on_a_corridor_of_dead_ends(solver: str) -> None:
    # four agents in a 2 x 4 block: many conflicts, so agents are merged into meta-agents
    free = np.array([[1, 1, 1, 1], [1, 1, 0, 1]], dtype=bool)
    instance = MapfInstance(
        free, ((1, 3), (1, 0), (0, 0), (0, 2)), ((0, 0), (0, 3), (1, 0), (1, 3))
    )
    optimum = brute_force_soc(instance)
    result = solve(instance, solver, w=1.5, time_limit_s=5)
    assert result.status == "success", result.message
    assert validate(instance, result.solution.paths).valid
    if solver == "cbs":
        assert result.soc == optimum
    else:
        assert result.lower_bound <= optimum <= result.soc <= 1.5 * optimum
