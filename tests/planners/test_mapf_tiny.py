"""Known tiny MAPF instances with hand-derived optima, for every solver, through the validator."""

from __future__ import annotations

import numpy as np
import pytest

from planners.mapf import SOLVERS, MapfInstance, solve, validate

# a corridor of five cells with one pocket below the middle one
POCKET = np.array([[1, 1, 1, 1, 1], [0, 0, 1, 0, 0]], dtype=bool)
OPTIMAL = ("cbs", "cbs-plain")


def _solved(instance: MapfInstance, solver: str):
    result = solve(instance, solver, time_limit_s=10)
    assert result.status == "success", result.message
    report = validate(instance, result.solution.paths)
    assert report.valid, report.errors
    assert (report.soc, report.makespan) == (result.soc, result.makespan)
    return result


@pytest.mark.parametrize("solver", SOLVERS)
def test_four_agents_rotate_around_a_2x2_cycle(solver: str) -> None:
    free = np.ones((2, 2), dtype=bool)
    cycle = ((0, 0), (0, 1), (1, 1), (1, 0))
    instance = MapfInstance(free, cycle, cycle[1:] + cycle[:1])
    result = _solved(instance, solver)
    assert result.soc == 4
    assert result.makespan == 1


@pytest.mark.parametrize("solver", [*OPTIMAL, "ecbs"])
def test_two_agents_swap_through_a_side_pocket(solver: str) -> None:
    # one agent waits a step, the other detours through the pocket: 5 + 6
    instance = MapfInstance(POCKET, ((0, 0), (0, 4)), ((0, 4), (0, 0)))
    result = _solved(instance, solver)
    if solver in OPTIMAL:
        assert result.soc == 11
        assert result.makespan == 6
    else:
        assert 11 <= result.soc <= 1.2 * 11
    dodger = next(p for p in result.solution.paths if (1, 2) in p)
    assert len(dodger) - 1 >= 6


@pytest.mark.parametrize("solver", SOLVERS)
def test_agent_steps_off_its_goal_to_let_another_pass(solver: str) -> None:
    instance = MapfInstance(POCKET, ((0, 2), (0, 0)), ((0, 2), (0, 4)))
    result = _solved(instance, solver)
    assert result.solution.paths[0][0] == result.solution.paths[0][-1] == (0, 2)
    assert (1, 2) in result.solution.paths[0]
    assert result.solution.costs == (3, 4)
    assert result.soc == 7


@pytest.mark.parametrize("solver", SOLVERS)
def test_solutions_are_deterministic(solver: str) -> None:
    from planners.mapf.generate import random_instance, random_map

    instance = random_instance(random_map(12, 12, 0.15, 3), 12, 5)
    first = solve(instance, solver, time_limit_s=20)
    second = solve(instance, solver, time_limit_s=20)
    assert first.status == second.status == "success"
    assert first.solution == second.solution
    assert validate(instance, first.solution.paths).valid
