"""Single-agent space-time search under constraints: A* and focal A* (the CBS / ECBS low levels).

States are ``(cell, t)`` with unit-cost moves and waits and the cached BFS distance as heuristic,
raised to ``earliest_finish - t`` when the goal is constrained later on (both consistent). A
``max_finish`` bound (target reasoning's ``l ≤ t``) prunes states that cannot reach the goal in
time. The goal counts only where the agent enters it (or starts there): an agent that waited on
its goal since before ``min_finish`` must leave and come back, so a state "just arrived at the
goal" is kept apart from "waiting on the goal". Beyond
the last time any constraint or avoidance entry mentions, ``(cell, t)`` and ``(cell, t + 1)`` have
the same future, so states are merged there ("time collapse"): the state space is finite and a
search with no solution ends instead of waiting forever.

- ``space_time_astar``: A* ordered by ``(f, conflicts, -g)``, i.e. among optimal paths the one
  with the fewest collisions with other agents' paths (the CAT tie-break of ICBS).
- ``focal_astar``: focal search (Pearl and Kim 1982; ECBS low level, Barer et al. 2014): expands
  the node with the fewest collisions among those with ``f ≤ w · f_min``; returns the path and
  ``f_min``, a lower bound on the optimal cost under these constraints.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from heapq import heappop, heappush

from planners.mapf.deadline import Deadline
from planners.mapf.grid_graph import UNREACHABLE, GridGraph
from planners.mapf.tables import ConflictAvoidanceTable, ConstraintTable

_CHECK_EVERY = 512


class SearchStats:
    """Counters shared by the high level and its low-level calls."""

    __slots__ = ("high", "low")

    def __init__(self) -> None:
        self.high = 0
        self.low = 0


def _path(cells: list[int], parents: list[int], node: int) -> list[int]:
    out = []
    while node >= 0:
        out.append(cells[node])
        node = parents[node]
    out.reverse()
    return out


def _bounds(
    graph: GridGraph,
    start: int,
    goal: int,
    table: ConstraintTable,
    cat: ConflictAvoidanceTable | None,
) -> tuple[int, int, list[int], int, int, Callable[[int, int], Sequence[int]]] | None:
    """``(earliest, latest, dist, horizon, span, moves)`` of a search: the first and last times
    the agent may finish at its goal, the distances to it, the first time from which states are
    merged (beyond every constraint and avoidance entry), the time span of a cell's state keys
    (``cell * span + t``; the goal entered at t is ``num_cells * span + t``) and the table's
    moves; None when no path can exist."""
    earliest = table.earliest_finish(goal)
    if earliest is None:
        return None
    dist = graph.distances(goal)
    if dist[start] >= UNREACHABLE:
        return None
    latest = UNREACHABLE if table.max_finish is None else table.max_finish
    if dist[start] > latest:
        return None
    horizon = max(table.horizon, earliest, 0 if cat is None else cat.horizon) + 1
    return earliest, latest, dist, horizon, horizon + 1, table.moves(graph.successors)


def space_time_astar(
    graph: GridGraph,
    start: int,
    goal: int,
    table: ConstraintTable,
    cat: ConflictAvoidanceTable | None,
    deadline: Deadline,
    stats: SearchStats,
) -> list[int] | None:
    """The cheapest path from ``start`` to ``goal`` (parked there) under ``table``, or None."""
    bounds = _bounds(graph, start, goal, table, cat)
    if bounds is None:
        return None
    earliest, latest, dist, horizon, span, moves = bounds
    n = graph.num_cells
    arrived = n * span  # key of the goal entered from another cell at t: arrived + t
    if cat is not None:
        cat_v, cat_e, cat_p = cat.vertex, cat.edge, cat.parked
    cells = [start]
    times = [0]
    parents = [-1]
    keys = [arrived if start == goal else start * span]
    heap = [(max(dist[start], earliest), 0, 0, 0)]
    closed: set[int] = set()
    best_conf: dict[int, int] = {}
    expanded = 0
    try:
        while heap:
            _f, conf, _, node = heappop(heap)
            cell = cells[node]
            t = times[node]
            key = keys[node]
            if key in closed:
                continue
            closed.add(key)
            expanded += 1
            if expanded % _CHECK_EVERY == 0:
                deadline.check()
            if key >= arrived and t >= earliest:
                return _path(cells, parents, node)
            nt = t + 1
            tn = nt * n
            for nc in moves(cell, nt):
                h = dist[nc]
                if nt + h > latest:
                    continue
                if earliest - nt > h:
                    h = earliest - nt
                tk = nt if nt < horizon else horizon
                nkey = arrived + tk if nc == goal and nc != cell else nc * span + tk
                if nkey in closed:
                    continue
                c = conf
                if cat is not None:
                    c += cat_v.get(tn + nc, 0)
                    if nc != cell:
                        c += cat_e.get((tn + cell) * n + nc, 0)
                    pa = cat_p.get(nc)
                    if pa is not None and nt >= pa:
                        c += 1
                if nt < horizon:
                    old = best_conf.get(nkey)
                    if old is not None and old <= c:
                        continue
                    best_conf[nkey] = c
                idx = len(cells)
                cells.append(nc)
                times.append(nt)
                parents.append(node)
                keys.append(nkey)
                heappush(heap, (nt + h, c, -nt, idx))
        return None
    finally:
        stats.low += expanded


def focal_astar(
    graph: GridGraph,
    start: int,
    goal: int,
    table: ConstraintTable,
    cat: ConflictAvoidanceTable,
    w: float,
    deadline: Deadline,
    stats: SearchStats,
) -> tuple[list[int], int] | None:
    """A path of cost ≤ w · optimum with few CAT collisions, and the lower bound ``f_min``."""
    bounds = _bounds(graph, start, goal, table, cat)
    if bounds is None:
        return None
    earliest, latest, dist, horizon, span, moves = bounds
    n = graph.num_cells
    arrived = n * span  # key of the goal entered from another cell at t: arrived + t
    cat_v, cat_e, cat_p = cat.vertex, cat.edge, cat.parked
    f0 = max(dist[start], earliest)
    cells, times, confs, parents = [start], [0], [0], [-1]
    keys = [arrived if start == goal else start * span]
    current: dict[int, int] = {keys[0]: 0}
    done: set[int] = set()
    open_heap = [(f0, 0)]
    focal = [(0, f0, 0, 0)]
    waiting: list[tuple[int, int]] = []
    threshold = int(w * f0 + 1e-9)
    nodes = (done, current, keys, confs, times)
    expanded = 0
    try:
        while True:
            picked = _pick(open_heap, focal, waiting, threshold, w, nodes)
            if picked is None:
                return None
            node, conf, f_min, threshold = picked
            done.add(node)
            expanded += 1
            if expanded % _CHECK_EVERY == 0:
                deadline.check()
            cell = cells[node]
            t = times[node]
            if keys[node] >= arrived and t >= earliest:
                return _path(cells, parents, node), f_min
            nt = t + 1
            tn = nt * n
            for nc in moves(cell, nt):
                h = dist[nc]
                if nt + h > latest:
                    continue
                if earliest - nt > h:
                    h = earliest - nt
                c = conf + cat_v.get(tn + nc, 0)
                if nc != cell:
                    c += cat_e.get((tn + cell) * n + nc, 0)
                pa = cat_p.get(nc)
                if pa is not None and nt >= pa:
                    c += 1
                tk = nt if nt < horizon else horizon
                nkey = arrived + tk if nc == goal and nc != cell else nc * span + tk
                old = current.get(nkey)
                if old is not None and times[old] <= nt and confs[old] <= c:
                    continue
                idx = len(cells)
                cells.append(nc)
                times.append(nt)
                f = nt + h
                confs.append(c)
                parents.append(node)
                keys.append(nkey)
                current[nkey] = idx
                heappush(open_heap, (f, idx))
                if f <= threshold:
                    heappush(focal, (c, f, -nt, idx))
                else:
                    heappush(waiting, (f, idx))
    finally:
        stats.low += expanded


def _pick(
    open_heap: list[tuple[int, int]],
    focal: list[tuple[int, int, int, int]],
    waiting: list[tuple[int, int]],
    threshold: int,
    w: float,
    nodes: tuple[set[int], dict[int, int], list[int], list[int], list[int]],
) -> tuple[int, int, int, int] | None:
    """The next node of a focal search, its conflicts, ``f_min`` and the focal bound
    ``w · f_min`` (FOCAL takes the waiting nodes that bound now admits), or None when OPEN is
    empty. ``nodes``: the expanded nodes, the live node of each state key, and the nodes' keys,
    conflicts and times; a node is live while unexpanded and the latest of its state."""
    done, current, keys, confs, times = nodes
    while open_heap and (
        open_heap[0][1] in done or current.get(keys[open_heap[0][1]]) != open_heap[0][1]
    ):
        heappop(open_heap)
    if not open_heap:
        return None
    f_min = open_heap[0][0]
    bound = int(w * f_min + 1e-9)
    if bound > threshold:
        threshold = bound
        while waiting and waiting[0][0] <= threshold:
            f, i = heappop(waiting)
            if i not in done and current.get(keys[i]) == i:
                heappush(focal, (confs[i], f, -times[i], i))
    # never empty here: threshold ≥ f_min, so the node at the top of OPEN is in FOCAL
    while focal[0][3] in done or current.get(keys[focal[0][3]]) != focal[0][3]:
        heappop(focal)
    conf, _f, _, node = heappop(focal)
    return node, conf, f_min, threshold
