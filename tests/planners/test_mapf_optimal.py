"""CBS and ECBS against the brute-force joint-state optimum on random tiny instances (hypothesis),
and on fixed instances where agents block each other in a dead end (issue 18)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from planners.mapf import MapfInstance, solve, validate
from planners.mapf.brute_force import brute_force_soc
from planners.mapf.model import InfeasibleInstanceError, check_instance

# a slow solve is a failure of the solver: tiny instances take milliseconds
TIME_LIMIT_S = 10.0
# plain CBS keeps its textbook weakness (it splits target conflicts one timestep at a time), so it
# is only held to instances it finishes quickly
PLAIN_TIME_LIMIT_S = 0.5

# goals in a dead-end corridor: one agent must leave its goal and come back
DEAD_END = np.array([[1, 1, 1, 1], [1, 1, 0, 1], [1, 0, 1, 1], [0, 1, 1, 0]], dtype=bool)
DEAD_END_GOALS = ((3, 2), (1, 3), (2, 2))
DEAD_ENDS = [
    MapfInstance(DEAD_END, starts=((0, 1), (0, 0), (2, 3)), goals=DEAD_END_GOALS),
    MapfInstance(DEAD_END, starts=((0, 0), (1, 1), (2, 3)), goals=DEAD_END_GOALS),
]


@st.composite
def tiny_instances(draw):
    rows = draw(st.integers(2, 4))
    cols = draw(st.integers(2, 4))
    free = np.array(draw(st.lists(st.booleans(), min_size=rows * cols, max_size=rows * cols)))
    free = free.reshape(rows, cols) | (np.arange(rows * cols).reshape(rows, cols) % 3 != 0)
    cells = [tuple(c) for c in np.argwhere(free).tolist()]
    k = draw(st.integers(min(2, len(cells) - 1), min(3, len(cells) - 1)))
    starts = draw(st.lists(st.sampled_from(cells), min_size=k, max_size=k, unique=True))
    goals = draw(st.lists(st.sampled_from(cells), min_size=k, max_size=k, unique=True))
    return MapfInstance(free, tuple(starts), tuple(goals))


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(tiny_instances())
def test_cbs_soc_equals_brute_force_optimum(instance: MapfInstance) -> None:
    try:
        check_instance(instance)
    except InfeasibleInstanceError:
        assume(False)
    optimum = brute_force_soc(instance)
    assume(optimum is not None)
    result = solve(instance, "cbs", time_limit_s=TIME_LIMIT_S)
    assert result.status == "success", result.message
    assert validate(instance, result.solution.paths).valid
    assert result.soc == optimum
    ecbs = solve(instance, "ecbs", w=1.5, time_limit_s=TIME_LIMIT_S)
    assert ecbs.status == "success", ecbs.message
    assert validate(instance, ecbs.solution.paths).valid
    assert ecbs.lower_bound <= optimum <= ecbs.soc <= 1.5 * optimum
    plain = solve(instance, "cbs-plain", time_limit_s=PLAIN_TIME_LIMIT_S)
    if plain.status == "success":
        assert validate(instance, plain.solution.paths).valid
        assert plain.soc == optimum
    else:
        assert plain.status == "timeout"


def test_brute_force_matches_a_hand_derived_optimum() -> None:
    pocket = np.array([[1, 1, 1, 1, 1], [0, 0, 1, 0, 0]], dtype=bool)
    assert brute_force_soc(MapfInstance(pocket, ((0, 0), (0, 4)), ((0, 4), (0, 0)))) == 11
    assert brute_force_soc(MapfInstance(pocket, ((0, 2), (0, 0)), ((0, 2), (0, 4)))) == 7
    corridor = np.ones((1, 4), dtype=bool)
    assert brute_force_soc(MapfInstance(corridor, ((0, 0), (0, 3)), ((0, 3), (0, 0)))) is None


@pytest.mark.parametrize("instance", DEAD_ENDS, ids=["first", "second"])
def test_dead_end_goals_have_optimum_32(instance: MapfInstance) -> None:
    assert brute_force_soc(instance) == 32


@pytest.mark.parametrize("instance", DEAD_ENDS, ids=["first", "second"])
def test_cbs_solves_dead_end_goals_optimally_in_two_seconds(instance: MapfInstance) -> None:
    result = solve(instance, "cbs", time_limit_s=2.0)
    assert result.status == "success", result.message
    assert validate(instance, result.solution.paths).valid
    assert result.soc == 32


@pytest.mark.parametrize("instance", DEAD_ENDS, ids=["first", "second"])
def test_ecbs_solves_dead_end_goals_within_its_bound(instance: MapfInstance) -> None:
    result = solve(instance, "ecbs", w=1.2, time_limit_s=2.0)
    assert result.status == "success", result.message
    assert validate(instance, result.solution.paths).valid
    assert result.lower_bound <= 32 <= result.soc <= 1.2 * 32
