"""Safe Interval Path Planning (Phillips and Likhachev, ICRA 2011) on a reservation table.

A state is a cell and one of its safe intervals (maximal runs of time steps in which the cell is
not reserved); its g-value is the earliest arrival time within that interval. Waiting is implicit:
from ``(cell, [lo, hi])`` reached at ``t`` a neighbour's interval ``[lo', hi']`` is entered at the
first ``t' ≥ max(t + 1, lo')`` with ``t' ≤ hi + 1`` and ``t' ≤ hi'`` whose move is not a swap with
a reserved move. The goal is reached in its last, unbounded interval, so the agent can stay.
"""

from __future__ import annotations

from heapq import heappop, heappush

from planners.mapf.deadline import Deadline
from planners.mapf.grid_graph import UNREACHABLE, GridGraph
from planners.mapf.low_level import SearchStats
from planners.mapf.tables import ConstraintTable

INF = 1 << 40


def safe_intervals(table: ConstraintTable, cell: int) -> list[tuple[int, int]]:
    """The maximal reservation-free time intervals ``[lo, hi]`` (inclusive) of ``cell``."""
    times = sorted(set(table.vertex_times.get(cell, ())))
    end = table.blocked_from.get(cell, INF)
    out = []
    lo = 0
    for t in times:
        if t >= end:
            break
        if t > lo:
            out.append((lo, t - 1))
        lo = t + 1
    if lo < end:
        out.append((lo, end - 1 if end < INF else INF))
    return out


def sipp(
    graph: GridGraph,
    start: int,
    goal: int,
    table: ConstraintTable,
    deadline: Deadline,
    stats: SearchStats,
) -> list[int] | None:
    """The earliest-arrival path from ``start`` to ``goal`` (parked there), or None."""
    dist = graph.distances(goal)
    if dist[start] >= UNREACHABLE:
        return None
    n = graph.num_cells
    edge = table.edge
    neighbours = graph.neighbours
    intervals: dict[int, list[tuple[int, int]]] = {}

    def ivs(cell: int) -> list[tuple[int, int]]:
        got = intervals.get(cell)
        if got is None:
            got = intervals[cell] = safe_intervals(table, cell)
        return got

    start_ivs = ivs(start)
    if not start_ivs or start_ivs[0][0] != 0:
        return None
    cells = [start]
    arrivals = [0]
    his = [start_ivs[0][1]]
    parents = [-1]
    best: dict[tuple[int, int], int] = {(start, his[0]): 0}
    heap = [(dist[start], 0, 0)]
    done: set[tuple[int, int]] = set()
    expanded = 0
    try:
        while heap:
            _f, _, node = heappop(heap)
            cell, t, hi = cells[node], arrivals[node], his[node]
            state = (cell, hi)
            if state in done:
                continue
            done.add(state)
            expanded += 1
            if expanded % 512 == 0:
                deadline.check()
            if cell == goal and hi >= INF:
                break
            for nc in neighbours[cell]:
                for lo2, hi2 in ivs(nc):
                    if lo2 > hi + 1:
                        break
                    if hi2 < t + 1:
                        continue
                    ta = max(t + 1, lo2)
                    last = min(hi + 1, hi2)
                    while ta <= last and (ta * n + cell) * n + nc in edge:
                        ta += 1
                    if ta > last:
                        continue
                    key = (nc, hi2)
                    if best.get(key, INF) <= ta:
                        continue
                    best[key] = ta
                    idx = len(cells)
                    cells.append(nc)
                    arrivals.append(ta)
                    his.append(hi2)
                    parents.append(node)
                    heappush(heap, (ta + dist[nc], -ta, idx))
        else:
            return None
    finally:
        stats.low += expanded
    return _path(cells, arrivals, parents, node)


def _path(cells: list[int], arrivals: list[int], parents: list[int], node: int) -> list[int]:
    """The cells per time step of the chain of states ending at ``node``, the waits filled in."""
    path: list[int] = []
    while node >= 0:
        parent = parents[node]
        if parent >= 0:
            path.extend([cells[node]] + [cells[parent]] * (arrivals[node] - arrivals[parent] - 1))
        else:
            path.append(cells[node])
        node = parent
    path.reverse()
    return path
