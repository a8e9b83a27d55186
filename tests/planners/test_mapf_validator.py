"""The validator catches every kind of broken solution and recomputes SOC and makespan."""

from __future__ import annotations

import numpy as np
import pytest

from planners.mapf import MapfInstance, validate

FREE = np.array([[1, 1, 1], [1, 0, 1], [1, 1, 1]], dtype=bool)
INSTANCE = MapfInstance(FREE, ((0, 0), (0, 2)), ((0, 2), (2, 2)), ("a", "b"))


def test_valid_solution_with_costs() -> None:
    paths = [
        [(0, 0), (0, 0), (0, 1), (0, 2)],
        [(0, 2), (1, 2), (2, 2), (2, 2), (2, 2)],
    ]
    report = validate(INSTANCE, paths)
    assert report.valid, report.errors
    assert report.soc == 3 + 2
    assert report.makespan == 3


def test_leaving_the_goal_counts_until_the_last_arrival() -> None:
    instance = MapfInstance(FREE, ((0, 0),), ((0, 1),))
    report = validate(instance, [[(0, 0), (0, 1), (0, 2), (0, 1)]])
    assert report.valid
    assert report.soc == 3


@pytest.mark.parametrize(
    ("paths", "needle"),
    [
        ([[(0, 0), (0, 1), (0, 2)], [(0, 2), (0, 2), (0, 2), (1, 2), (2, 2)]], "both in (0, 2)"),
        ([[(0, 0), (0, 1), (0, 2)], [(0, 2), (0, 1), (0, 0), (1, 0)]], "both in (0, 1)"),
        (
            [
                [(0, 0), (0, 1), (0, 2)],
                [(0, 2), (0, 2), (0, 1), (0, 0), (1, 0), (2, 0), (2, 1), (2, 2)],
            ],
            "swap",
        ),
        ([[(0, 0), (0, 2)], [(0, 2), (1, 2), (2, 2)]], "jumps"),
        ([[(0, 0), (1, 0), (1, 1), (1, 2), (0, 2)], [(0, 2), (1, 2), (2, 2)]], "obstacle"),
        ([[(0, 0), (0, 1)], [(0, 2), (1, 2), (2, 2)]], "not at its goal"),
        ([[(1, 0), (0, 0), (0, 1), (0, 2)], [(0, 2), (1, 2), (2, 2)]], "not at its start"),
        ([[(0, 0), (-1, 0), (0, 0), (0, 1), (0, 2)], [(0, 2), (1, 2), (2, 2)]], "outside"),
        ([[(0, 0), (0, 1), (0, 2)]], "1 paths for 2 agents"),
    ],
)
def test_broken_solutions_are_reported(paths, needle: str) -> None:
    report = validate(INSTANCE, paths)
    assert not report.valid
    assert any(needle in e for e in report.errors), report.errors


def test_target_conflict_with_a_parked_agent() -> None:
    # b never moves (its path ends at t = 0); a passes through b's goal at t = 1
    instance = MapfInstance(FREE, ((0, 0), (0, 1)), ((0, 2), (0, 1)), ("a", "b"))
    report = validate(instance, [[(0, 0), (0, 1), (0, 2)], [(0, 1)]])
    assert not report.valid
    assert any("t=1: a and b both in (0, 1)" in e for e in report.errors), report.errors


def test_a_move_through_a_closed_edge_is_reported() -> None:
    instance = MapfInstance(FREE, ((0, 0),), ((0, 1),), ("a",))
    open_right = np.array([[False, True], [True, True], [True, True]])
    assert validate(instance, [[(0, 0), (0, 1)]]).valid
    report = validate(instance, [[(0, 0), (0, 1)]], open_right=open_right)
    assert any("closed" in e for e in report.errors), report.errors
    # the way back is closed as well; other moves stay open
    back = MapfInstance(FREE, ((0, 1),), ((1, 0),), ("a",))
    assert not validate(back, [[(0, 1), (0, 0), (1, 0)]], open_right=open_right).valid
    down = np.ones((2, 3), dtype=bool)
    assert validate(back, [[(0, 1), (0, 0), (1, 0)]], open_down=down).valid
