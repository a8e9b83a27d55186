"""Prioritized planning: the priority order is respected, and restarts rescue a bad order."""

from __future__ import annotations

import numpy as np
import pytest

from planners.mapf import MapfInstance, solve, validate
from planners.mapf.generate import random_instance, random_map
from planners.mapf.grid_graph import GridGraph

POCKET = np.array([[1, 1, 1, 1, 1], [0, 0, 1, 0, 0]], dtype=bool)


@pytest.mark.parametrize("solver", ["pp", "sipp-pp"])
@pytest.mark.parametrize("order", [(0, 1), (1, 0)])
def test_the_higher_priority_agent_keeps_its_shortest_path(solver: str, order) -> None:
    # both shortest paths cross the centre at t = 1; only the lower-priority agent yields
    free = np.ones((3, 3), dtype=bool)
    instance = MapfInstance(free, ((1, 0), (0, 1)), ((1, 2), (2, 1)))
    result = solve(instance, solver, order=order, max_restarts=0)
    assert result.status == "success"
    assert validate(instance, result.solution.paths).valid
    assert result.details["order"] == list(order)
    first, second = order
    assert result.solution.costs[first] == 2
    assert result.solution.costs[second] == 3


@pytest.mark.parametrize("solver", ["pp", "sipp-pp"])
def test_every_agent_avoids_all_higher_priority_agents_only(solver: str) -> None:
    free = random_map(16, 16, 0.1, 1)
    instance = random_instance(free, 25, 2)
    order = tuple(reversed(range(25)))
    result = solve(instance, solver, order=order, max_restarts=0)
    assert result.status == "success"
    graph = GridGraph(free)
    top = order[0]
    dist = graph.distances(graph.cell(instance.goals[top]))[graph.cell(instance.starts[top])]
    assert result.solution.costs[top] == dist
    for j in range(1, 25):
        sub = [order[i] for i in range(j + 1)]
        part = MapfInstance(
            free,
            tuple(instance.starts[a] for a in sub),
            tuple(instance.goals[a] for a in sub),
        )
        assert validate(part, [result.solution.paths[a] for a in sub]).valid


@pytest.mark.parametrize("solver", ["pp", "sipp-pp"])
def test_a_failing_order_is_restarted(solver: str) -> None:
    # agent 0 parked on its goal in the corridor blocks agent 1 unless agent 1 goes first
    instance = MapfInstance(POCKET, ((0, 2), (0, 0)), ((0, 2), (0, 4)))
    stuck = solve(instance, solver, order=(0, 1), max_restarts=0)
    assert stuck.status == "failed"
    assert stuck.solution is None
    rescued = solve(instance, solver, order=(0, 1), seed=0)
    assert rescued.status == "success"
    assert rescued.details["attempts"] > 1
    assert rescued.details["order"] == [1, 0]
    assert validate(instance, rescued.solution.paths).valid


def test_bad_order_is_rejected() -> None:
    instance = MapfInstance(POCKET, ((0, 2), (0, 0)), ((0, 2), (0, 4)))
    with pytest.raises(ValueError, match="permutation"):
        solve(instance, "pp", order=(0, 0))


@pytest.mark.parametrize("solver", ["pp", "sipp-pp"])
def test_pp_gives_up_once_every_order_failed(solver: str) -> None:
    # a swap through a side pocket: both orders fail, restarts cannot help (cbs solves it)
    instance = MapfInstance(POCKET, ((0, 0), (0, 4)), ((0, 4), (0, 0)))
    result = solve(instance, solver, time_limit_s=30)
    assert result.status == "failed"
    assert result.details["attempts"] == 2
    assert result.runtime_s < 1.0
    assert solve(instance, "cbs", time_limit_s=5).soc == 11


def test_closed_moves_of_a_grid_graph_are_not_taken() -> None:
    # a 2 x 3 grid whose top row's two right cells are not joined: the way goes round below
    free = np.ones((2, 3), dtype=bool)
    open_right = np.array([[True, False], [True, True]])
    graph = GridGraph(free, open_right=open_right)
    assert graph.cell((0, 2)) not in graph.neighbours[graph.cell((0, 1))]
    assert graph.distances(graph.cell((0, 2)))[graph.cell((0, 1))] == 3
    instance = MapfInstance(free, ((0, 1),), ((0, 2),))
    result = solve(instance, "sipp-pp", graph=graph)
    assert result.status == "success"
    assert result.solution.costs == (3,)
    with pytest.raises(ValueError):
        GridGraph(free, open_down=np.ones((2, 3), dtype=bool))
