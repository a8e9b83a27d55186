"""Frontiers as tasks of the market: a goal to drive to, worth the area it is expected to reveal.

A frontier's task (:func:`goal_task`) is the shortest path the market can sell: from the
frontier's goal (:class:`planners.frontiers.Frontier`) one short ``step`` on towards its
centroid, so its one piece is driven, and the task done, once the robot has reached the goal.
Its ``area_m2`` is the frontier's expected information gain, its ``time_s`` zero: what it costs
a robot is the travel to it, priced by the robot itself.

As maps grow, frontiers move and vanish (Yamauchi 1997 re-extracts them after every move). A
task's frontier is still there while some frontier cell lies within ``match_m`` of its goal
(:func:`still_there`); a frontier is new unless its goal lies within ``match_m`` of the goal of
a task alive or already reached (:func:`new_frontiers`), so a frontier that stays where a robot
stood (unknown cells its lidar cannot see) is not sold again, while a long frontier one robot
heads for at one end can still be sold at the other.

The value of a call is Burgard et al. 2005's utility (:func:`planners.frontiers.
discounted_utility`: the gain, discounted for each goal another robot is already headed to)
at ``seconds_per_m2`` of travel per m² (their β trade-off of utility against cost, eq. 6):
:func:`call_values`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from planners.auction.tasks import Task
from planners.frontiers import Frontier, discounted_utility
from planners.grid import GridMap


def goal_task(task_id: str, frontier: Frontier, step: float) -> Task:
    """The task of driving to ``frontier``'s goal and ``step`` (m) on towards its centroid
    (along +x when the two coincide)."""
    goal = np.asarray(frontier.goal, dtype=float)
    heading = np.asarray(frontier.centroid, dtype=float) - goal
    norm = float(np.hypot(*heading))
    unit = heading / norm if norm > 1e-9 else np.array([1.0, 0.0])
    path = np.stack([goal, goal + step * unit])
    return Task(task_id, path, frontier.information_gain, 0.0, (), "frontier")


def _nearest(points: np.ndarray, to: np.ndarray) -> np.ndarray:
    """(N,) distance from each of ``points`` (N, 2) to the nearest of ``to`` (M, 2); inf if
    M = 0."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    to = np.asarray(to, dtype=float).reshape(-1, 2)
    if len(to) == 0:
        return np.full(len(points), np.inf)
    return np.linalg.norm(points[:, None, :] - to[None, :, :], axis=-1).min(axis=1)


def frontier_points(frontiers: Sequence[Frontier], grid: GridMap) -> np.ndarray:
    """(K, 2) world centres of all frontier cells of ``frontiers`` (on ``grid``)."""
    if not frontiers:
        return np.zeros((0, 2))
    return grid.cell_to_world(np.concatenate([f.cells for f in frontiers]))


def still_there(
    goals: np.ndarray, frontiers: Sequence[Frontier], grid: GridMap, match_m: float
) -> np.ndarray:
    """(N,) whether each of ``goals`` ((N, 2) world) has a frontier cell within ``match_m``."""
    return _nearest(goals, frontier_points(frontiers, grid)) <= match_m


def new_frontiers(
    frontiers: Sequence[Frontier],
    taken: np.ndarray,
    match_m: float,
    gone: np.ndarray | None = None,
    max_gone: int = 2,
) -> list[Frontier]:
    """The frontiers whose goal lies farther than ``match_m`` from each of ``taken`` ((M, 2)
    world: the goals of tasks alive or reached) and within ``match_m`` of fewer than
    ``max_gone`` of ``gone`` (the goals of tasks whose frontier vanished): a frontier that
    vanishes as a robot nears it and comes back once it leaves (a corner seen from afar) is
    sold ``max_gone`` times, not for ever."""
    if not frontiers:
        return []
    goals = np.array([f.goal for f in frontiers], dtype=float)
    gone = np.zeros((0, 2)) if gone is None else np.asarray(gone, dtype=float).reshape(-1, 2)
    near_gone = (np.linalg.norm(goals[:, None, :] - gone[None, :, :], axis=-1) <= match_m).sum(1)
    return [
        f
        for f, d, n in zip(frontiers, _nearest(goals, taken), near_gone, strict=True)
        if d > match_m and n < max_gone
    ]


def call_values(
    gains: np.ndarray,
    goals: np.ndarray,
    headed: np.ndarray,
    sensor_range: float,
    seconds_per_m2: float,
) -> np.ndarray:
    """(N,) seconds each of ``goals`` (gains in m²) is worth once other robots are headed to
    ``headed`` ((M, 2)): the discounted utility (Burgard et al. 2005, eq. 5) at
    ``seconds_per_m2``."""
    return seconds_per_m2 * discounted_utility(gains, goals, headed, sensor_range)
