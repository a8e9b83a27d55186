"""Corridor and rectangle reasoning: one split for a whole family of symmetric conflicts.

Li, Harabor, Stuckey, Ma, Gange and Koenig, "Pairwise symmetry reasoning for multi-agent path
finding search", AIJ 301, 2021 (sections 4 and 5). Both kinds end in two *branches*, each a tuple
of vertex constraints for one agent, such that every pair of conflict-free paths satisfies at
least one branch; so CBS that splits on them stays optimal (and ECBS keeps its bound), while
one split does what vertex constraints would do one timestep at a time.

**Corridor** (section 5). Agents a1 and a2 meet inside a chain of cells of degree 2 (a corridor
of k edges between its ends e1 and e2) going opposite ways: a1 enters at e1 and needs e2, a2
enters at e2 and needs e1. Let t1 be the earliest time a1 can be at e2 under its constraints,
t1' the earliest without passing the corridor (a bypass), and t2, t2' the same for a2 at e1.
Range constraints (the paper's corridor split):

    a1 is not at e2 at any time in [t1, min(t1' - 1, t2 + k)]
    a2 is not at e1 at any time in [t2, min(t2' - 1, t1 + k)]

Why every solution keeps one: if a1 is at e2 at T1 ≤ t1' - 1, it came through the corridor; if
a2 is at e1 at T2 ≤ t2' - 1, so did it. Two agents crossing a one-lane chain the opposite ways at
overlapping times collide, so one went through first, e.g. a1: a2 then left e2 after T1 and needs
k more steps, T2 ≥ T1 + k + 1 > t1 + k. Earliest times are found by space-time A* with time
collapse (``earliest_arrival``); any lower bound of them keeps the argument, so the agents'
maximum lengths are ignored there. Neither start may lie inside the corridor (strictly between
its ends), or "came through the corridor" would not follow.

**Rectangle** (section 4, the barrier constraints). Agents a1 and a2 start at s1, s2 (time 0)
and both move Manhattan-optimally (every step toward the goal-side corner) up to their vertex
conflict, in directions that agree on both axes. Mirror the grid so both move down and right.
With Rs = (max rows, max cols) of the starts, one agent (the *top* one) starts in Rs's column at
or above it, the other (the *left* one) in Rs's row at or left of it. For a corner Rg no further
than either agent's Manhattan-optimal stretch goes, the top agent's barrier is the bottom side
of the rectangle Rs..Rg, each cell x at time |x - s_top| (its Manhattan distance from the start),
and the left agent's barrier is the right side, at |x - s_left|. A path that is at a barrier cell
at that time has moved monotonically from its start, so the top agent crossed the rectangle
from its top side to its bottom side and the left agent from the left side to the right side;
two such 4-connected paths share a cell, and both reach it at the same time (the starts have
the same row + column sum, since both reached the conflict cell Manhattan-optimally at the same
time). So the two paths collide, and every solution keeps one of the barriers. Rg is the
largest corner (within both agents' Manhattan-optimal stretches) whose barriers the current
paths both cross, so the split removes them.

Cardinality of both kinds is decided exactly with MDDs (``mdd.mdd_blocks``): a branch raises its
agent's cost when every path of the current cost violates it, which keeps the CG heuristic
admissible.
"""

from __future__ import annotations

from heapq import heappop, heappush

import numpy as np

from planners.mapf.constraints import VERTEX, Constraint
from planners.mapf.deadline import Deadline
from planners.mapf.grid_graph import UNREACHABLE, GridGraph
from planners.mapf.tables import ConstraintTable

# one branch of a split: constraints on a single agent (``constraint[1]``), all to hold together
Branch = tuple[Constraint, ...]

_CHECK_EVERY = 512


def earliest_arrival(
    graph: GridGraph,
    start: int,
    target: int,
    table: ConstraintTable,
    banned: tuple[int, int] | None,
    bound: int,
    deadline: Deadline,
) -> int:
    """The earliest time the agent can be at ``target`` under ``table`` without the move
    ``banned`` (either way), or ``bound`` if it cannot be there before ``bound``.

    Space-time A* on ``(cell, t)`` with the true distance as heuristic (admissible with a move
    banned too); beyond the table's horizon only parked cells matter, so times collapse there.
    """
    dist = graph.distances(target)
    if dist[start] >= UNREACHABLE or dist[start] >= bound:
        return bound
    moves = table.moves(graph.successors)
    horizon = table.horizon + 1
    span = horizon + 1
    seen = {start * span}
    heap = [(dist[start], 0, start)]
    popped = 0
    while heap:
        f, t, cell = heappop(heap)
        if f >= bound:
            return bound
        if cell == target:
            return t
        popped += 1
        if popped % _CHECK_EVERY == 0:
            deadline.check()
        nt = t + 1
        for nc in moves(cell, nt):
            if banned is not None and nc != cell and (cell, nc) in (banned, banned[::-1]):
                continue
            key = nc * span + (nt if nt < horizon else horizon)
            if key in seen or dist[nc] >= UNREACHABLE:
                continue
            seen.add(key)
            heappush(heap, (nt + dist[nc], nt, nc))
    return bound


def _at(pos: np.ndarray, agent: int, t: int) -> int:
    """The agent's cell at time t (paths padded with their last cell)."""
    return int(pos[agent, min(t, pos.shape[1] - 1)])


def _entry(graph: GridGraph, pos: np.ndarray, agent: int, t: int) -> tuple[int, int]:
    """Where and when the agent entered the degree-2 cells it is in at time t (its start if it
    has been in them since time 0): walk its path back while the cell has two neighbours."""
    t = min(t, pos.shape[1] - 1)
    while t > 0 and len(graph.neighbours[int(pos[agent, t])]) == 2:
        t -= 1
    return int(pos[agent, t]), t


def _chain(graph: GridGraph, first: int, second: int, end: int) -> list[int] | None:
    """The cells from ``first`` through ``second`` to ``end`` along a chain of degree-2 cells,
    or None if the chain ends (a cell of another degree) before reaching ``end``."""
    cells = [first, second]
    limit = graph.num_cells
    while cells[-1] != end:
        cell = cells[-1]
        nbrs = graph.neighbours[cell]
        if len(nbrs) != 2 or len(cells) > limit:
            return None
        cells.append(nbrs[0] if nbrs[1] == cells[-2] else nbrs[1])
    return cells


def _range(agent: int, cell: int, lo: int, hi: int) -> Branch:
    """The range constraint "agent not at cell at any time in [lo, hi]" as vertex constraints."""
    return tuple((VERTEX, agent, cell, -1, t) for t in range(lo, hi + 1))


def _violates(pos: np.ndarray, branch: Branch) -> bool:
    """Whether the current (padded) path of the branch's agent breaks one of its constraints."""
    return any(_at(pos, c[1], c[4]) == c[2] for c in branch)


def corridor_branches(
    graph: GridGraph,
    pos: np.ndarray,
    conflict: tuple[int, int, int, int, int],
    tables: tuple[ConstraintTable, ConstraintTable],
    deadline: Deadline,
) -> tuple[Branch, Branch] | None:
    """The corridor split of a vertex or swap conflict ``(t, a, b, u, v)`` (``conflicts``) on
    the padded paths ``pos``, or None if it is no corridor conflict; ``tables``: a's and b's
    constraint tables. Branch 0 constrains a, branch 1 constrains b."""
    t, a, b, u, v = conflict
    degree = graph.neighbours
    if v < 0:
        if len(degree[u]) != 2:
            return None
        at_a = at_b = t
    elif len(degree[u]) == 2:
        at_a, at_b = t - 1, t  # a swap: a in u one step before, b in u at t
    elif len(degree[v]) == 2:
        at_a, at_b = t, t - 1
    else:
        return None
    (ea, ta), (eb, tb) = _entry(graph, pos, a, at_a), _entry(graph, pos, b, at_b)
    if ea == eb:
        return None
    # a's first move after entering, into the corridor toward b's entry
    horizon = pos.shape[1]
    na = next((int(pos[a, s]) for s in range(ta + 1, horizon) if pos[a, s] != ea), -1)
    if na < 0 or not (pos[a, ta:] == eb).any() or not (pos[b, tb:] == ea).any():
        return None
    chain = _chain(graph, ea, na, eb)
    if chain is None:
        return None
    inside = set(chain[1:-1])
    if int(pos[a, 0]) in inside or int(pos[b, 0]) in inside:
        return None
    k = len(chain) - 1
    starts = (int(pos[a, 0]), int(pos[b, 0]))
    t1 = earliest_arrival(graph, starts[0], eb, tables[0], None, UNREACHABLE, deadline)
    t2 = earliest_arrival(graph, starts[1], ea, tables[1], None, UNREACHABLE, deadline)
    if t1 >= UNREACHABLE or t2 >= UNREACHABLE:
        return None
    t1_bypass = earliest_arrival(
        graph, starts[0], eb, tables[0], (chain[0], chain[1]), t2 + k + 1, deadline
    )
    t2_bypass = earliest_arrival(
        graph, starts[1], ea, tables[1], (chain[-1], chain[-2]), t1 + k + 1, deadline
    )
    first = _range(a, eb, t1, min(t1_bypass - 1, t2 + k))
    second = _range(b, ea, t2, min(t2_bypass - 1, t1 + k))
    if not first or not second or not _violates(pos, first) or not _violates(pos, second):
        return None
    return first, second


def _stretch(
    pos: np.ndarray, agent: int, x: tuple[int, int], t: int, cols: int
) -> tuple[tuple[int, int], int] | None:
    """The agent's start (row, column) and the last time of its Manhattan-optimal stretch from
    it (every step one further from the start), or None if it did not reach ``x`` at ``t`` so."""
    s = divmod(int(pos[agent, 0]), cols)
    if abs(x[0] - s[0]) + abs(x[1] - s[1]) != t:
        return None
    end = t
    while end + 1 < pos.shape[1]:
        g = divmod(int(pos[agent, end + 1]), cols)
        if abs(g[0] - s[0]) + abs(g[1] - s[1]) != end + 1:
            break
        end += 1
    return s, end


def _corner(
    rs: tuple[int, int],
    x: tuple[int, int],
    far: tuple[int, int],
    first_col: dict[int, int],
    first_row: dict[int, int],
) -> tuple[int, int] | None:
    """The corner Rg of the largest rectangle from ``rs`` (area at least 2) between the conflict
    cell ``x`` and ``far`` whose bottom side the top agent and right side the left agent both
    cross (``first_col``, ``first_row``), in normalized coordinates; None if there is none."""
    best: tuple[int, int, int] | None = None
    for r in range(x[0], far[0] + 1):
        for c in range(far[1], x[1] - 1, -1):
            if first_col[r] <= c and first_row[c] <= r:
                area = (r - rs[0] + 1) * (c - rs[1] + 1)
                if best is None or area > best[0]:
                    best = (area, r, c)
                break
    if best is None or best[0] < 2:
        return None
    return best[1], best[2]


def rectangle_branches(
    graph: GridGraph, pos: np.ndarray, t: int, a: int, b: int, cell: int
) -> tuple[Branch, Branch] | None:
    """The rectangle split (barrier constraints) of a vertex conflict between ``a`` and ``b`` in
    ``cell`` at time t, or None if it is no rectangle conflict. Branch 0 constrains a."""
    cols = graph.cols
    x = divmod(cell, cols)
    stretch_a, stretch_b = _stretch(pos, a, x, t, cols), _stretch(pos, b, x, t, cols)
    if stretch_a is None or stretch_b is None:
        return None
    (sa, ea), (sb, eb) = stretch_a, stretch_b
    ga, gb = divmod(int(pos[a, ea]), cols), divmod(int(pos[b, eb]), cols)
    signs = []
    for axis in (0, 1):
        da = (ga[axis] > sa[axis]) - (ga[axis] < sa[axis])
        db = (gb[axis] > sb[axis]) - (gb[axis] < sb[axis])
        if da * db < 0 or da == db == 0:
            return None
        signs.append(da or db)
    dr, dc = signs

    def norm(rc: tuple[int, int]) -> tuple[int, int]:
        return rc[0] * dr, rc[1] * dc

    na, nb = norm(sa), norm(sb)
    if na[0] + na[1] != nb[0] + nb[1]:
        return None
    rs = (max(na[0], nb[0]), max(na[1], nb[1]))
    if na[1] == rs[1] and nb[0] == rs[0]:
        top, left = a, b
    elif nb[1] == rs[1] and na[0] == rs[0]:
        top, left = b, a
    else:
        return None
    end_of = {a: ea, b: eb}
    # first column the top agent has on each row, first row the left agent has on each column
    first_col: dict[int, int] = {}
    for s in range(end_of[top] + 1):
        r, c = norm(divmod(int(pos[top, s]), cols))
        first_col.setdefault(r, c)
    first_row: dict[int, int] = {}
    for s in range(end_of[left] + 1):
        r, c = norm(divmod(int(pos[left, s]), cols))
        first_row.setdefault(c, r)
    g_top, g_left = (
        norm(divmod(int(pos[top, end_of[top]]), cols)),
        norm(divmod(int(pos[left, end_of[left]]), cols)),
    )
    far = (min(g_top[0], g_left[0]), min(g_top[1], g_left[1]))
    corner = _corner(rs, norm(x), far, first_col, first_row)
    if corner is None:
        return None
    rg_r, rg_c = corner
    starts = {
        top: norm(divmod(int(pos[top, 0]), cols)),
        left: norm(divmod(int(pos[left, 0]), cols)),
    }

    def barrier(agent: int, cells: list[tuple[int, int]]) -> Branch:
        s = starts[agent]
        out = []
        for r, c in cells:
            real = (r * dr) * cols + c * dc
            if graph.free.flat[real]:
                out.append((VERTEX, agent, real, -1, (r - s[0]) + (c - s[1])))
        return tuple(out)

    bottom = barrier(top, [(rg_r, c) for c in range(rs[1], rg_c + 1)])
    right = barrier(left, [(r, rg_c) for r in range(rs[0], rg_r + 1)])
    if not _violates(pos, bottom) or not _violates(pos, right):
        return None
    return (bottom, right) if top == a else (right, bottom)
