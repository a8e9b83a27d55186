"""A brute-force optimum for tiny MAPF instances, independent of the solvers: the reference that
``fleet bench mapf --tiny`` and the property tests check them against.

A* over joint configurations, every agent moving at once (no operator decomposition, no
constraints, none of the solvers' code), in the model of ``model``: vertex and swap conflicts are
forbidden and an agent pays until it reaches its goal for the last time. To charge that cost it
remembers, per agent, how long it has been sitting at its goal: leaving the goal pays those
waits back. The heuristic (sum of the agents' true distances to their goals, by BFS) is
admissible and consistent, so the first goal configuration popped is optimal (Hart, Nilsson and
Raphael 1968). States costing more than ``max_soc`` are not searched, which keeps the search
finite on unsolvable instances.
"""

from __future__ import annotations

import heapq
from collections import deque
from itertools import product

from planners.mapf.model import Cell, MapfInstance

MAX_SOC = 60


def brute_force_soc(instance: MapfInstance, max_soc: int = MAX_SOC) -> int | None:
    """The optimal sum of costs, or None if there is no solution costing at most ``max_soc``."""
    rows, cols = instance.shape
    free = instance.free

    def moves(cell: Cell) -> list[Cell]:
        r, c = cell
        out = [cell]
        for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            nr, nc = r + dr, c + dc
            if 0 <= nr < rows and 0 <= nc < cols and free[nr, nc]:
                out.append((nr, nc))
        return out

    def distances(goal: Cell) -> dict[Cell, int]:
        dist = {goal: 0}
        queue = deque([goal])
        while queue:
            cell = queue.popleft()
            for nxt in moves(cell)[1:]:
                if nxt not in dist:
                    dist[nxt] = dist[cell] + 1
                    queue.append(nxt)
        return dist

    goals = instance.goals
    dists = [distances(g) for g in goals]
    if any(s not in d for s, d in zip(instance.starts, dists, strict=True)):
        return None

    def h(pos: tuple[Cell, ...]) -> int:
        return sum(d[p] for d, p in zip(dists, pos, strict=True))

    k = instance.num_agents
    start = (instance.starts, (0,) * k)
    best = {start: 0}
    heap = [(h(instance.starts), 0, start)]
    while heap:
        _f, cost, state = heapq.heappop(heap)
        if cost > best[state]:
            continue
        pos, waits = state
        if pos == goals:
            return cost
        for nxt in product(*(moves(p) for p in pos)):
            if len(set(nxt)) < k:
                continue
            if any(
                nxt[i] == pos[j] and nxt[j] == pos[i]
                for i in range(k)
                for j in range(i + 1, k)
                if nxt[i] != pos[i]
            ):
                continue
            step = 0
            new_waits = []
            for i, (p, q) in enumerate(zip(pos, nxt, strict=True)):
                if q == goals[i] and p == goals[i]:
                    new_waits.append(waits[i] + 1)
                else:
                    step += 1 + waits[i]
                    new_waits.append(0)
            key = (nxt, tuple(new_waits))
            new_cost = cost + step
            f = new_cost + h(nxt)
            if f <= max_soc and new_cost < best.get(key, max_soc + 1):
                best[key] = new_cost
                heapq.heappush(heap, (f, new_cost, key))
    return None
