"""Frontiers as tasks: the goal task, whether its frontier is still there, which frontiers
are new, and what a call is worth."""

import numpy as np
import pytest

from planners.frontier_tasks import call_values, goal_task, new_frontiers, still_there
from planners.frontiers import Frontier
from planners.grid import GridMap

RES = 0.1


def frontier(cells: list[tuple[int, int]], goal: tuple[float, float], gain: float = 2.0):
    rc = np.array(cells)
    centroid = tuple((rc.mean(axis=0)[::-1] + 0.5) * RES)
    return Frontier(rc, len(cells) * RES, centroid, goal, gain)


GRID = GridMap(np.zeros((50, 50), bool), np.zeros((50, 50), bool), RES, (0.0, 0.0))
# a vertical frontier at x = 2.05 from y = 1.05 to 1.95; its goal at its middle
WALL = frontier([(r, 20) for r in range(10, 20)], (2.05, 1.45))


def test_a_goal_task_drives_to_the_goal_and_a_step_on_towards_the_centroid():
    f = frontier([(10, 20), (11, 20), (12, 20)], (2.05, 1.05), gain=3.5)
    task = goal_task("f001", f, 0.05)
    assert task.id == "f001" and task.pieces == 1
    assert task.entry.tolist() == pytest.approx([2.05, 1.05])
    # the centroid lies at y = 1.15: the step goes up
    assert task.exit.tolist() == pytest.approx([2.05, 1.10])
    assert task.area_m2 == 3.5 and task.time_s == 0.0
    on_goal = goal_task("f002", frontier([(10, 20)], (2.05, 1.05)), 0.05)
    assert on_goal.exit.tolist() == pytest.approx([2.10, 1.05])


def test_a_goal_is_still_a_frontier_while_a_frontier_cell_lies_within_the_match():
    goals = np.array([[2.05, 1.45], [2.6, 1.45], [2.05, 2.6], [5.0, 5.0]])
    there = still_there(goals, [WALL], GRID, 0.5)
    assert there.tolist() == [True, False, False, False]
    assert not still_there(goals, [], GRID, 0.5).any()


def test_a_frontier_is_new_unless_its_goal_is_near_a_goal_sold_or_reached():
    other = frontier([(40, 40), (40, 41)], (4.05, 4.05))
    taken = np.array([[2.05, 1.8]])  # 0.35 m from WALL's goal
    assert new_frontiers([WALL, other], taken, 0.5) == [other]
    assert new_frontiers([WALL, other], taken, 0.3) == [WALL, other]
    assert new_frontiers([WALL, other], np.zeros((0, 2)), 0.5) == [WALL, other]


def test_a_frontier_that_keeps_vanishing_is_sold_only_so_often():
    none = np.zeros((0, 2))
    once = np.array([[2.05, 1.6]])  # its task went once: the frontier vanished, then came back
    assert new_frontiers([WALL], none, 0.5, once) == [WALL]
    twice = np.array([[2.05, 1.6], [2.1, 1.5]])
    assert new_frontiers([WALL], none, 0.5, twice) == []
    assert new_frontiers([WALL], none, 0.5, twice, max_gone=3) == [WALL]
    far = np.array([[4.0, 4.0], [4.1, 4.0]])  # elsewhere: no bearing on this one
    assert new_frontiers([WALL], none, 0.5, far) == [WALL]


def test_a_call_is_worth_its_gain_discounted_near_goals_robots_are_headed_to():
    goals = np.array([[0.0, 0.0], [4.0, 0.0]])
    gains = np.array([3.0, 3.0])
    headed = np.array([[1.0, 0.0]])  # 1 m from the first goal: P = 1 - 1/2
    values = call_values(gains, goals, headed, sensor_range=2.0, seconds_per_m2=2.0)
    assert values.tolist() == pytest.approx([2.0 * 3.0 * 0.5, 2.0 * 3.0])
