"""Multi-valued decision diagrams (Sharon et al. 2013), reduced to what ICBS needs.

The MDD of an agent with cost C under its constraints holds every ``(cell, t)`` on some path of
cost exactly C (one that arrives at its goal at C, from another cell). A conflict is cardinal for
an agent when the MDD has width one at the conflict (every optimal path goes through it), so the
constraint that forbids it raises the agent's cost (Boyarski et al., "ICBS", IJCAI 2015). We keep
only ``singletons[t]``: the cell when the level has width one, else -1.
"""

from __future__ import annotations

from planners.mapf.grid_graph import GridGraph
from planners.mapf.tables import ConstraintTable


def mdd_singletons(
    graph: GridGraph, start: int, goal: int, cost: int, table: ConstraintTable
) -> tuple[int, ...]:
    """For t in 0..cost, the only cell of MDD level t, or -1 where the level is wider."""
    dist = graph.distances(goal)
    moves = table.moves(graph.successors)
    levels: list[dict[int, list[int]]] = [{start: []}]
    for t in range(1, cost + 1):
        budget = cost - t
        layer: dict[int, list[int]] = {}
        for cell in levels[-1]:
            for nc in moves(cell, t):
                if dist[nc] > budget:
                    continue
                parents = layer.get(nc)
                if parents is None:
                    layer[nc] = [cell]
                else:
                    parents.append(cell)
        levels.append(layer)
    singles = [-1] * (cost + 1)
    alive = {goal} if goal in levels[cost] else set()
    if cost and alive:
        # a path of cost exactly ``cost`` arrives at the goal then, it was not already there
        levels[cost][goal] = [p for p in levels[cost][goal] if p != goal]
    for t in range(cost, -1, -1):
        if len(alive) == 1:
            singles[t] = next(iter(alive))
        if t:
            layer = levels[t]
            alive = {p for c in alive for p in layer[c]}
    return tuple(singles)


def mdd_blocks(
    graph: GridGraph,
    start: int,
    goal: int,
    cost: int,
    table: ConstraintTable,
    forbidden: set[tuple[int, int]],
) -> bool:
    """Whether every path of cost exactly ``cost`` under ``table`` is in one of the ``forbidden``
    ``(cell, t)`` vertices, so that forbidding them all raises the agent's cost (a branch of
    corridor or rectangle reasoning is cardinal for its agent, Li et al., AIJ 2021).

    A forward sweep over the MDD's levels that skips the forbidden vertices; the agent then
    stays at its goal, so a forbidden goal at any time from ``cost`` on blocks every path.
    """
    if any(cell == goal and t >= cost for cell, t in forbidden):
        return True
    dist = graph.distances(goal)
    if cost == 0 or (start, 0) in forbidden:
        return cost != 0 or start != goal or (start, 0) in forbidden
    moves = table.moves(graph.successors)
    layer = {start}
    for t in range(1, cost + 1):
        budget = cost - t
        nxt: set[int] = set()
        for cell in layer:
            for nc in moves(cell, t):
                if t == cost and (nc != goal or cell == goal):
                    continue
                if dist[nc] > budget or (nc, t) in forbidden:
                    continue
                nxt.add(nc)
        if not nxt:
            return True
        layer = nxt
    return False
