"""Optimal joint-space search for a few agents: A* with operator decomposition (OD).

Standley, "Finding optimal solutions to cooperative pathfinding problems", AAAI 2010: a joint
state holds every agent's cell; OD moves one agent at a time, so a state has at most five
successors instead of 5^m, and intermediate states (some agents moved) are searched like full
ones. MA-CBS (Sharon et al., "Meta-agent conflict-based search for optimal multi-agent path
finding", SoCS 2012) plans a meta-agent with such a search, under the CBS constraints of its
members, while internal conflicts are simply not generated.

Cost model (``model``): an agent pays every timestep until it reaches its goal for the last time.
Instead of counting an agent's waits at its goal and paying them back when it leaves, each agent
carries a *finished* flag: when it arrives at its goal (or starts there) the search branches into
"finished" (it stays there for good and pays nothing more; allowed only if its constraints let
it stay from that time on) and "not finished" (it pays one per step and must leave and come back).
The cost of a plan is then exactly the model's SOC.

The heuristic sums, over unfinished agents, the true distance to the goal (2 for an agent sitting
on its goal unfinished: it must leave and return), raised to ``earliest_finish - t``; it is
consistent under OD. Beyond the last time any constraint or avoidance entry mentions, states
that differ only in time have the same future and are merged, so the state space is finite and
the search proves a group unsolvable instead of running forever. Ties among equal ``f`` break
toward fewer collisions with the other agents' paths (a conflict-avoidance table), then deeper.
"""

from __future__ import annotations

from collections.abc import Sequence
from heapq import heappop, heappush

from planners.mapf.deadline import Deadline
from planners.mapf.grid_graph import UNREACHABLE, GridGraph
from planners.mapf.low_level import SearchStats
from planners.mapf.tables import ConflictAvoidanceTable, ConstraintTable

_CHECK_EVERY = 256


class JointSearchLimit(Exception):
    """The joint search expanded more states than its budget allowed (the group is too hard)."""


def joint_astar(
    graph: GridGraph,
    starts: Sequence[int],
    goals: Sequence[int],
    tables: Sequence[ConstraintTable],
    cat: ConflictAvoidanceTable | None,
    deadline: Deadline,
    stats: SearchStats,
    max_expanded: int | None = None,
) -> list[list[int]] | None:
    """Paths of minimum sum of costs for the agents together, each under its own ``tables[i]``.

    Returns None when no conflict-free joint plan satisfies the constraints; raises
    JointSearchLimit after ``max_expanded`` expansions and SearchTimeout at the deadline.
    """
    m = len(starts)
    n = graph.num_cells
    succ = graph.successors
    dists = [graph.distances(g) for g in goals]
    earliest: list[int] = []
    latest: list[int] = []
    for i in range(m):
        e = tables[i].earliest_finish(goals[i])
        if e is None or dists[i][starts[i]] >= UNREACHABLE:
            return None
        earliest.append(e)
        mf = tables[i].max_finish
        latest.append(UNREACHABLE if mf is None else mf)
        if dists[i][starts[i]] > latest[i]:
            return None
    horizon = max([tb.horizon for tb in tables] + earliest + [cat.horizon if cat else 0]) + 1
    full = (1 << m) - 1

    def h_of(i: int, cell: int, t: int) -> int:
        d = dists[i][cell] or 2
        e = earliest[i] - t
        return d if d >= e else e

    # node arrays: old cells at time t, new cells of the agents already moved, finished mask
    n_pos: list[tuple[int, ...]] = []
    n_new: list[tuple[int, ...]] = []
    n_idx: list[int] = []
    n_fin: list[int] = []
    n_t: list[int] = []
    n_g: list[int] = []
    n_parent: list[int] = []
    best: dict[tuple, tuple[int, int]] = {}
    heap: list[tuple[int, int, int, int]] = []

    def settle(
        pos: tuple[int, ...], new: tuple[int, ...], i: int, fin: int, t: int
    ) -> tuple[tuple[int, ...], tuple[int, ...], int, int]:
        """Move finished agents (they stay) until an unfinished agent is next or all are done."""
        while i < m and fin >> i & 1:
            new = (*new, pos[i])
            i += 1
        if i == m:
            pos, new, i, t = new, (), 0, t + 1
            if fin != full:
                while fin >> i & 1:
                    new = (*new, pos[i])
                    i += 1
        return pos, new, i, t

    def push(
        pos: tuple[int, ...],
        new: tuple[int, ...],
        i: int,
        fin: int,
        t: int,
        g: int,
        conf: int,
        parent: int,
    ) -> None:
        key = (t if t < horizon else horizon, i, pos, new, fin)
        old = best.get(key)
        if old is not None and old <= (g, conf):
            return
        best[key] = (g, conf)
        h = 0
        for j in range(m):
            if not fin >> j & 1:
                h += h_of(j, new[j], t + 1) if j < i else h_of(j, pos[j], t)
        idx = len(n_pos)
        n_pos.append(pos)
        n_new.append(new)
        n_idx.append(i)
        n_fin.append(fin)
        n_t.append(t)
        n_g.append(g)
        n_parent.append(parent)
        heappush(heap, (g + h, conf, -g, idx))

    starts_t = tuple(starts)
    can_finish = [i for i in range(m) if starts[i] == goals[i] and earliest[i] == 0]
    for choice in range(1 << len(can_finish)):
        fin = 0
        for bit, i in enumerate(can_finish):
            if choice >> bit & 1:
                fin |= 1 << i
        if fin == full:
            return [[s] for s in starts]
        pos, new, i, t = settle(starts_t, (), 0, fin, 0)
        push(pos, new, i, fin, t, 0, 0, -1)

    if cat is not None:
        cat_v, cat_e, cat_p = cat.vertex, cat.edge, cat.parked
    expanded = 0
    try:
        while heap:
            _f, conf, neg_g, node = heappop(heap)
            pos, new, i, fin, t = n_pos[node], n_new[node], n_idx[node], n_fin[node], n_t[node]
            key = (t if t < horizon else horizon, i, pos, new, fin)
            if best.get(key) != (-neg_g, conf):
                continue
            best[key] = (-1, -1)  # closed: nothing is cheaper than this
            if fin == full:
                return _paths(n_pos, n_t, n_parent, node, m)
            expanded += 1
            if expanded % _CHECK_EVERY == 0:
                deadline.check()
            if max_expanded is not None and expanded > max_expanded:
                raise JointSearchLimit
            g = -neg_g + 1
            u = pos[i]
            goal = goals[i]
            table = tables[i]
            vertex, edge, blocked = table.vertex, table.edge, table.blocked_from
            dist = dists[i]
            nt = t + 1
            tn = nt * n
            for v in succ[u]:
                if tn + v in vertex:
                    continue
                bf = blocked.get(v)
                if bf is not None and nt >= bf:
                    continue
                if v != u and (tn + u) * n + v in edge:
                    continue
                if nt + dist[v] > latest[i]:
                    continue
                clash = False
                for j in range(i):
                    if new[j] == v or (v != u and new[j] == u and pos[j] == v):
                        clash = True
                        break
                if clash:
                    continue
                for j in range(i + 1, m):
                    if fin >> j & 1 and pos[j] == v:
                        clash = True
                        break
                if clash:
                    continue
                c = conf
                if cat is not None:
                    c += cat_v.get(tn + v, 0)
                    if v != u:
                        c += cat_e.get((tn + u) * n + v, 0)
                    pa = cat_p.get(v)
                    if pa is not None and nt >= pa:
                        c += 1
                moved = (*new, v)
                if v != goal or nt + 2 <= latest[i]:
                    p2, n2, i2, t2 = settle(pos, moved, i + 1, fin, t)
                    push(p2, n2, i2, fin, t2, g, c, node)
                if v == goal and u != goal and earliest[i] <= nt:
                    done = fin | 1 << i
                    p2, n2, i2, t2 = settle(pos, moved, i + 1, done, t)
                    push(p2, n2, i2, done, t2, g, c, node)
        return None
    finally:
        stats.low += expanded


def _paths(
    n_pos: list[tuple[int, ...]], n_t: list[int], n_parent: list[int], node: int, m: int
) -> list[list[int]]:
    """Each agent's cells over time, read off the chain of states that ends at ``node``."""
    at: dict[int, tuple[int, ...]] = {}
    while node >= 0:
        at.setdefault(n_t[node], n_pos[node])
        node = n_parent[node]
    horizon = max(at)
    return [[at[t][j] for t in range(horizon + 1)] for j in range(m)]
