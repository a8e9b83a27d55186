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

The heuristic sums, over unfinished agents, the true distance to the goal around the goals of the
finished agents (they never move again), 2 for an agent sitting on its goal unfinished (it must
leave and return), raised to ``earliest_finish - t``; a state in which a parked agent cuts
another off from its goal is dropped at once, which is what makes agents in dead ends cheap.
Searches of 2..4 agents on small maps that run past ``PAIR_AFTER`` expansions also take the
maximum, over partitions of the agents into pairs, of the sum of the pairs' exact joint costs
alone (a pairwise pattern database, ``_pair_values``): on dense tiny grids it cuts expansions
three- to fivefold. That part is admissible but not consistent under OD, so states are
re-opened when reached more cheaply (A* with re-expansion stays optimal).

Beyond the last time any constraint or avoidance entry mentions, states that differ only in time
have the same future and are merged, so the state space is finite and the search proves a group
unsolvable instead of running forever. Ties among equal ``f`` break toward fewer collisions with
the other agents' paths (a conflict-avoidance table), then deeper.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from heapq import heapify, heappop, heappush
from itertools import combinations
from typing import NamedTuple

import numpy as np

from planners.mapf.deadline import Deadline
from planners.mapf.grid_graph import UNREACHABLE, GridGraph
from planners.mapf.low_level import SearchStats
from planners.mapf.model import InfeasibleInstanceError
from planners.mapf.tables import ConflictAvoidanceTable, ConstraintTable

_CHECK_EVERY = 256
# after this many expansions a search of 2..4 agents on a map of at most PAIR_MAX_CELLS cells
# builds the pairwise heuristic (a few milliseconds per pair) and re-sorts its open list
PAIR_AFTER = 1000
PAIR_MAX_CELLS = 64


class JointSearchLimit(Exception):
    """The joint search expanded more states than its budget allowed (the group is too hard)."""


def group_plan(
    graph: GridGraph,
    starts: Sequence[int],
    goals: Sequence[int],
    agents: Sequence[int],
    cat: ConflictAvoidanceTable | None,
    deadline: Deadline,
    stats: SearchStats,
    budget: int,
) -> list[list[int]]:
    """The optimal plan of a new meta-agent (MA-CBS, Sharon et al. 2012: merge and restart):
    ``agents`` planned jointly without constraints. Raises JointSearchLimit past ``budget``
    expansions, and InfeasibleInstanceError when the group has no plan even on its own."""
    paths = joint_astar(
        graph,
        [starts[i] for i in agents],
        [goals[i] for i in agents],
        [ConstraintTable(graph.num_cells) for _ in agents],
        cat,
        deadline,
        stats,
        budget,
    )
    if paths is None:
        raise InfeasibleInstanceError(
            f"no solution: agents {list(agents)} have no joint plan even on their own"
        )
    return paths


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
    heuristic = _heuristic(graph, goals, dists, earliest)
    front = _frontier(m, horizon, heuristic)
    push, settle, best, heap = front.push, front.settle, front.best, front.heap
    full = (1 << m) - 1
    can_finish = [i for i in range(m) if starts[i] == goals[i] and earliest[i] == 0]
    for choice in range(1 << len(can_finish)):
        fin = 0
        for bit, i in enumerate(can_finish):
            if choice >> bit & 1:
                fin |= 1 << i
        if fin == full:
            return [[s] for s in starts]
        pos, new, i, t = settle(tuple(starts), (), 0, fin, 0)
        push(pos, new, i, fin, t, 0, 0, -1, -1)
    limits = _Limits(dists, earliest, latest)
    expand = _expander(graph, goals, tables, cat, limits, front, heuristic.h_of)
    n_fin, n_key = front.n_fin, front.n_key
    expanded = 0
    try:
        while heap:
            f, conf, neg_g, node = heappop(heap)
            key = n_key[node]
            if best.get(key) != (-neg_g, conf):
                continue
            if n_fin[node] == full:
                return _paths(front.n_pos, front.n_t, front.n_parent, node, m)
            expanded += 1
            if expanded % _CHECK_EVERY == 0:
                deadline.check()
            if expanded == PAIR_AFTER and 2 <= m <= 4 and n <= PAIR_MAX_CELLS:
                heuristic.build_pairs()
                front.rescore()
                heappush(heap, (f, conf, neg_g, node))
                best[key] = (-neg_g, conf)
                continue
            if max_expanded is not None and expanded > max_expanded:
                raise JointSearchLimit
            expand(node, conf, -neg_g + 1)
        return None
    finally:
        stats.low += expanded


class _Limits(NamedTuple):
    """Per agent: its distances to its goal, and the first and last times it may finish."""

    dists: list[list[int]]
    earliest: list[int]
    latest: list[int]


class _Heuristic(NamedTuple):
    """``h_of(i, cell, t, fin)``: agent i's single-agent heuristic, the finished agents in
    ``fin`` parked; ``h_pairs(pos, new, i, fin, t)``: the pairwise one of a joint state, once
    ``build_pairs()`` has filled ``pair_values`` (until then it is not used)."""

    h_of: Callable[[int, int, int, int], int]
    h_pairs: Callable[[tuple[int, ...], tuple[int, ...], int, int, int], int]
    build_pairs: Callable[[], None]
    pair_values: dict[tuple[int, int], list[int]]


def _heuristic(
    graph: GridGraph, goals: Sequence[int], dists: list[list[int]], earliest: list[int]
) -> _Heuristic:
    """The heuristics of a joint search (see the module)."""
    m = len(goals)
    n = graph.num_cells
    # alone[i][mask]: agent i's cost to finish from each cell, the agents in mask parked
    alone: list[list[list[int] | None]] = [[None] * (1 << m) for _ in range(m)]

    def dist_around(i: int, fin: int) -> list[int]:
        """Agent i's distances to its goal avoiding the goals of the finished agents."""
        mask = fin & ~(1 << i)
        if not mask:
            return dists[i]
        return _distances(graph, goals[i], {goals[j] for j in range(m) if mask >> j & 1})

    def single(i: int, fin: int) -> list[int]:
        """Agent i's distances around the finished agents; on its goal (unfinished) 2, as it
        must step off and come back."""
        mask = fin & ~(1 << i)
        got = alone[i][mask]
        if got is None:
            got = alone[i][mask] = _alone(graph, goals[i], dist_around(i, mask)).tolist()
        return got

    def h_of(i: int, cell: int, t: int, fin: int) -> int:
        d = single(i, fin)[cell]
        e = earliest[i] - t
        return d if d >= e else e

    pair_values: dict[tuple[int, int], list[int]] = {}
    partitions = _partitions(m)

    def h_pairs(pos: tuple[int, ...], new: tuple[int, ...], i: int, fin: int, t: int) -> int:
        """The best sum, over a partition of the agents into pairs (and a single), of the pairs'
        joint costs alone (``_pair_values``) and the singles' heuristics."""
        top = 0
        for pairs, singles in partitions:
            total = 0
            for a, b in pairs:
                fa, fb = fin >> a & 1, fin >> b & 1
                if fa and fb:
                    continue
                if fa or fb:
                    x = b if fa else a
                    total += h_of(x, new[x], t + 1, fin) if x < i else h_of(x, pos[x], t, fin)
                elif (a < i) == (b < i):
                    cells = new if a < i else pos
                    total += pair_values[(a, b)][cells[a] * n + cells[b]]
                else:
                    # one of the two has moved and paid for this step already
                    total += pair_values[(a, b)][pos[a] * n + pos[b]] - 1
            for x in singles:
                if not fin >> x & 1:
                    total += h_of(x, new[x], t + 1, fin) if x < i else h_of(x, pos[x], t, fin)
            if total > top:
                top = total
        return top

    def build_pairs() -> None:
        """Compute the pair tables."""
        for a, b in combinations(range(m), 2):
            alone_a = _alone(graph, goals[a], dist_around(a, 1 << b))
            alone_b = _alone(graph, goals[b], dist_around(b, 1 << a))
            pair_values[(a, b)] = _pair_values(graph, goals[a], goals[b], alone_a, alone_b)

    return _Heuristic(h_of, h_pairs, build_pairs, pair_values)


class _Frontier(NamedTuple):
    """The states of a joint search (parallel lists: cells at time t, new cells of the agents
    already moved, next agent, finished mask, t, parent, key, single-agent heuristic), the best
    (g, conflicts) per key, the open list, and the functions that fill them."""

    n_pos: list[tuple[int, ...]]
    n_new: list[tuple[int, ...]]
    n_idx: list[int]
    n_fin: list[int]
    n_t: list[int]
    n_parent: list[int]
    n_key: list[tuple]
    n_h: list[int]
    best: dict[tuple, tuple[int, int]]
    heap: list[tuple[int, int, int, int]]
    push: Callable[..., None]
    settle: Callable[..., tuple[tuple[int, ...], tuple[int, ...], int, int]]
    rescore: Callable[[], None]


def _frontier(m: int, horizon: int, heuristic: _Heuristic) -> _Frontier:
    """An empty frontier of a joint search of ``m`` agents merging states from ``horizon`` on."""
    full = (1 << m) - 1
    h_of, h_pairs, pair_values = heuristic.h_of, heuristic.h_pairs, heuristic.pair_values
    n_pos: list[tuple[int, ...]] = []
    n_new: list[tuple[int, ...]] = []
    n_idx: list[int] = []
    n_fin: list[int] = []
    n_t: list[int] = []
    n_parent: list[int] = []
    n_key: list[tuple] = []
    n_h: list[int] = []
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
        h: int,
    ) -> None:
        """Queue a state; ``h`` is its single-agent heuristic, or -1 to compute it anew."""
        key = (t if t < horizon else horizon, i, pos, new, fin)
        old = best.get(key)
        if old is not None and old <= (g, conf):
            return
        if h < 0:
            h = 0
            for j in range(m):
                if not fin >> j & 1:
                    h += h_of(j, new[j], t + 1, fin) if j < i else h_of(j, pos[j], t, fin)
        if h >= UNREACHABLE:
            return
        hp = h_pairs(pos, new, i, fin, t) if pair_values else 0
        if hp >= UNREACHABLE:
            return
        best[key] = (g, conf)
        idx = len(n_pos)
        n_key.append(key)
        n_h.append(h)
        n_pos.append(pos)
        n_new.append(new)
        n_idx.append(i)
        n_fin.append(fin)
        n_t.append(t)
        n_parent.append(parent)
        heappush(heap, (g + (h if h >= hp else hp), conf, -g, idx))

    def rescore() -> None:
        """Re-sort the open list under the pairwise heuristic, now that it is built."""
        for k, (_f, conf, neg_g, idx) in enumerate(heap):
            hp = h_pairs(n_pos[idx], n_new[idx], n_idx[idx], n_fin[idx], n_t[idx])
            heap[k] = (-neg_g + max(n_h[idx], hp), conf, neg_g, idx)
        heapify(heap)

    lists = (n_pos, n_new, n_idx, n_fin, n_t, n_parent, n_key, n_h)
    return _Frontier(*lists, best, heap, push, settle, rescore)


def _expander(
    graph: GridGraph,
    goals: Sequence[int],
    tables: Sequence[ConstraintTable],
    cat: ConflictAvoidanceTable | None,
    limits: _Limits,
    front: _Frontier,
    h_of: Callable[[int, int, int, int], int],
) -> Callable[[int, int, int], None]:
    """``expand(node, conf, g)``: queue the successors of a state (OD: the next agent moves),
    its collisions with the avoidance table ``conf`` and its cost-to-come ``g`` after the move;
    ``h_of``: the single-agent heuristic (``_Heuristic``)."""
    m = len(goals)
    n = graph.num_cells
    moves = [table.moves(graph.successors) for table in tables]
    dists, earliest, latest = limits
    n_pos, n_new, n_idx, n_fin, n_t = front[:5]
    n_h = front.n_h
    push, settle = front.push, front.settle
    if cat is not None:
        cat_v, cat_e, cat_p = cat.vertex, cat.edge, cat.parked

    def expand(node: int, conf: int, g: int) -> None:
        pos, new, i, fin, t = n_pos[node], n_new[node], n_idx[node], n_fin[node], n_t[node]
        u = pos[i]
        goal = goals[i]
        dist = dists[i]
        # the heuristic without agent i's part, which the move changes
        h_rest = n_h[node] - h_of(i, u, t, fin)
        nt = t + 1
        tn = nt * n
        for v in moves[i](u, nt):
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
                hv = h_rest + h_of(i, v, nt, fin)
                if i + 1 < m and not fin >> (i + 1) & 1:
                    push(pos, moved, i + 1, fin, t, g, c, node, hv)
                else:
                    p2, n2, i2, t2 = settle(pos, moved, i + 1, fin, t)
                    push(p2, n2, i2, fin, t2, g, c, node, hv)
            if v == goal and u != goal and earliest[i] <= nt:
                done = fin | 1 << i
                p2, n2, i2, t2 = settle(pos, moved, i + 1, done, t)
                push(p2, n2, i2, done, t2, g, c, node, -1)

    return expand


def _partitions(m: int) -> list[tuple[list[tuple[int, int]], list[int]]]:
    """The ways to cover 2..4 agents by as many disjoint pairs as fit, and a single if m is odd."""
    if not 2 <= m <= 4:
        return []
    out = []
    for first in combinations(range(m), 2):
        rest = [x for x in range(m) if x not in first]
        if m == 4:
            second = (rest[0], rest[1])
            if first < second:
                out.append(([first, second], []))
        else:
            out.append(([first], rest))
    return out


def _alone(graph: GridGraph, goal: int, dist: list[int]) -> np.ndarray:
    """One agent's cost to finish from every cell, the other agent parked (``dist`` goes around
    it): its distance, or 2 on its own goal (it must step off and come back)."""
    out = np.array(dist, dtype=np.int64)
    back = any(dist[c] == 1 for c in graph.neighbours[goal])
    out[goal] = 2 if back else UNREACHABLE
    return out


def _pair_values(
    graph: GridGraph, goal_a: int, goal_b: int, alone_a: np.ndarray, alone_b: np.ndarray
) -> list[int]:
    """``V[a * n + b]``: the least cost for two unfinished agents at cells a and b to both
    finish, ignoring every other agent and every constraint (a pattern database of the pair,
    as in Felner, Korf and Hanan, "Additive pattern database heuristics", JAIR 2004).

    Value iteration over all pairs of cells at once: a step costs 2 (both pay) and leads to
    another unfinished pair, or finishes one agent on arrival at its goal (the other then pays
    ``alone``), or both. Moves follow the model: no shared cell, no swap.
    """
    n = graph.num_cells
    succ = np.full((n, 5), n, dtype=np.int64)  # n: no such move
    for cell, nexts in enumerate(graph.successors):
        succ[cell, : len(nexts)] = nexts
    to_a = succ[:, :, None, None]
    to_b = succ[None, None, :, :]
    at_a = np.arange(n)[:, None, None, None]
    at_b = np.arange(n)[None, None, :, None]
    valid = (to_a < n) & (to_b < n) & (to_a != to_b) & ~((to_a == at_b) & (to_b == at_a))
    inf = UNREACHABLE
    alone_a = np.append(alone_a, inf)
    alone_b = np.append(alone_b, inf)
    done_a = (to_a == goal_a) & (at_a != goal_a)
    done_b = (to_b == goal_b) & (at_b != goal_b)
    finish = np.minimum(np.where(done_a, alone_b[to_b], inf), np.where(done_b, alone_a[to_a], inf))
    finish = np.where(done_a & done_b, 0, finish)
    finish = np.where(valid, np.minimum(finish + 2, inf), inf)
    best_finish = finish.min(axis=(1, 3))
    values = np.full((n + 1, n + 1), inf, dtype=np.int64)
    to_a, to_b = np.broadcast_arrays(to_a, to_b)
    while True:
        cont = np.where(valid, values[to_a, to_b] + 2, inf).min(axis=(1, 3))
        new = np.minimum(np.minimum(cont, best_finish), inf)
        if np.array_equal(new, values[:n, :n]):
            return new.ravel().tolist()
        values[:n, :n] = new


def _distances(graph: GridGraph, goal: int, blocked: set[int]) -> list[int]:
    """BFS distances to ``goal`` through cells not in ``blocked``; from a blocked cell, one more
    than from its best neighbour (UNREACHABLE where there is no way)."""
    dist = [UNREACHABLE] * graph.num_cells
    dist[goal] = 0
    frontier = [goal]
    d = 0
    while frontier:
        d += 1
        nxt = []
        for cell in frontier:
            for nb in graph.neighbours[cell]:
                if dist[nb] == UNREACHABLE and nb not in blocked:
                    dist[nb] = d
                    nxt.append(nb)
        frontier = nxt
    for cell in blocked:
        # an agent still on a parked goal (the parked agent is following it in) steps off
        dist[cell] = min(
            UNREACHABLE, 1 + min((dist[nb] for nb in graph.neighbours[cell]), default=UNREACHABLE)
        )
    return dist


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
