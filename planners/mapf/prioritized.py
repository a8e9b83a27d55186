"""Prioritized planning (Silver 2005; Erdmann and Lozano-Pérez 1987) with randomized restarts.

Agents are planned one at a time in priority order, each against a reservation table holding the
paths of all higher-priority agents (cells, moves, and their goals from arrival on), with
space-time A* or SIPP as the single-agent planner. PP is fast but incomplete: when an agent finds
no path, the whole plan restarts with a fresh random order (seeded, so runs are reproducible),
until one succeeds or the deadline passes (Bennewitz et al. 2002 search over orders similarly).
A plan depends only on the order, so once every order of a small group has failed (all k! of
them, tracked up to ``EXHAUSTIVE_AGENTS`` agents) restarts cannot help and PP gives up.
"""

from __future__ import annotations

import random
from collections.abc import Sequence
from math import factorial

from planners.mapf.deadline import Deadline
from planners.mapf.grid_graph import GridGraph
from planners.mapf.low_level import SearchStats, space_time_astar
from planners.mapf.sipp import sipp
from planners.mapf.tables import ConstraintTable

LOW_LEVELS = ("astar", "sipp")
# up to this many agents PP remembers the orders it tried and stops when all k! have failed
EXHAUSTIVE_AGENTS = 6


def plan_in_order(
    graph: GridGraph,
    starts: Sequence[int],
    goals: Sequence[int],
    order: Sequence[int],
    low_level: str,
    deadline: Deadline,
    stats: SearchStats,
) -> list[list[int]] | int:
    """Paths for every agent planned in ``order``, or the agent that found no path."""
    table = ConstraintTable(graph.num_cells)
    paths: list[list[int] | None] = [None] * len(starts)
    for agent in order:
        if low_level == "sipp":
            path = sipp(graph, starts[agent], goals[agent], table, deadline, stats)
        else:
            path = space_time_astar(
                graph, starts[agent], goals[agent], table, None, deadline, stats
            )
        if path is None:
            return agent
        table.reserve_path(path)
        paths[agent] = path
    return paths  # type: ignore[return-value]


def prioritized(
    graph: GridGraph,
    starts: Sequence[int],
    goals: Sequence[int],
    order: Sequence[int] | None,
    low_level: str,
    seed: int,
    max_restarts: int | None,
    deadline: Deadline,
    stats: SearchStats,
) -> tuple[list[list[int]] | None, tuple[int, ...], int]:
    """(paths or None, the order that was used last, number of orders tried).

    ``order`` defaults to the agents' index order; ``max_restarts=None`` restarts until the
    deadline raises SearchTimeout, or until every order has failed (small groups only).
    """
    if low_level not in LOW_LEVELS:
        raise ValueError(f"low_level must be one of {LOW_LEVELS}, got {low_level!r}")
    k = len(starts)
    current = list(range(k)) if order is None else list(order)
    if sorted(current) != list(range(k)):
        raise ValueError(f"order must be a permutation of 0..{k - 1}, got {list(current)}")
    graph.precompute(goals)
    rng = random.Random(seed)
    attempts = 0
    orders = factorial(k) if k <= EXHAUSTIVE_AGENTS else None
    failed: set[tuple[int, ...]] = set()
    while True:
        attempts += 1
        stats.high += 1
        result = plan_in_order(graph, starts, goals, current, low_level, deadline, stats)
        if not isinstance(result, int):
            return result, tuple(current), attempts
        if max_restarts is not None and attempts > max_restarts:
            return None, tuple(current), attempts
        if orders is not None:
            failed.add(tuple(current))
            if len(failed) == orders:
                return None, tuple(current), attempts
        deadline.check()
        rng.shuffle(current)
        while orders is not None and tuple(current) in failed:
            rng.shuffle(current)
