"""Infeasible instances are rejected before search; every solver honours its time limit."""

from __future__ import annotations

import numpy as np
import pytest

from planners.mapf import SOLVERS, InfeasibleInstanceError, MapfInstance, check_instance, solve

OPEN = np.ones((3, 4), dtype=bool)


@pytest.mark.parametrize(
    ("starts", "goals", "free", "reason"),
    [
        (((0, 0),), ((5, 0),), OPEN, "outside"),
        (((-1, 0),), ((0, 0),), OPEN, "outside"),
        (((0, 0),), ((1, 1),), np.array([[1, 1, 1], [1, 0, 1]], bool), "obstacle"),
        (((1, 1),), ((0, 0),), np.array([[1, 1, 1], [1, 0, 1]], bool), "obstacle"),
        (((0, 0), (0, 0)), ((1, 1), (2, 2)), OPEN, "share the start"),
        (((0, 0), (0, 1)), ((2, 2), (2, 2)), OPEN, "share the goal"),
        (((0, 0),), ((0, 2),), np.array([[1, 0, 1], [1, 0, 1]], bool), "unreachable"),
    ],
)
def test_infeasible_instances_are_rejected_with_a_reason(starts, goals, free, reason) -> None:
    instance = MapfInstance(free, starts, goals)
    with pytest.raises(InfeasibleInstanceError, match=reason):
        check_instance(instance)
    for solver in SOLVERS:
        result = solve(instance, solver, time_limit_s=1)
        assert result.status == "infeasible"
        assert reason in result.message
        assert result.solution is None
        assert result.expanded == 0


# what each solver says about an instance without solution: CBS and ECBS merge the two agents
# and the joint search proves it, plain CBS splits until the deadline, PP tries both orders
UNSOLVABLE = {
    "cbs": "infeasible",
    "ecbs": "infeasible",
    "cbs-plain": "timeout",
    "pp": "failed",
    "sipp-pp": "failed",
}


@pytest.mark.parametrize("solver", SOLVERS)
def test_an_unsolvable_swap_ends_without_a_solution(solver: str) -> None:
    # two agents swapping ends of a corridor with no room to pass: no solution exists
    corridor = np.ones((1, 4), dtype=bool)
    instance = MapfInstance(corridor, ((0, 0), (0, 3)), ((0, 3), (0, 0)))
    check_instance(instance)
    result = solve(instance, solver, time_limit_s=0.3)
    assert result.status == UNSOLVABLE[solver]
    assert result.solution is None
    if result.status == "timeout":
        assert "0.3" in result.message
    else:
        assert result.runtime_s < 0.3
        assert "no " in result.message


def test_a_zero_time_limit_times_out_on_a_real_instance() -> None:
    from planners.mapf.generate import random_instance, random_map

    instance = random_instance(random_map(32, 32, 0.1, 0), 60, 0)
    assert solve(instance, "cbs", time_limit_s=0.0).status == "timeout"


def test_unknown_solver_is_rejected() -> None:
    with pytest.raises(ValueError, match="solver must be one of"):
        solve(MapfInstance(OPEN, ((0, 0),), ((1, 1),)), "astar")
