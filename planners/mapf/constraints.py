"""The constraints of CBS and ECBS: how conflicts are split, and the tables the low levels read.

- Vertex and edge conflicts split into one vertex / edge constraint per agent (Sharon et al.,
  AIJ 2015).
- Target conflicts: agent a is at agent b's goal at a time t at which b has already arrived
  there for good (t ≥ l_b, the length of b's path). Target reasoning (Li et al., "Pairwise
  symmetry reasoning for multi-agent path finding search", AIJ 2021, section 6; first in Li et
  al., "New techniques for pairwise symmetry breaking in multi-agent path finding", ICAPS 2020)
  branches on b's length instead: ``l_b > t`` (b may not stay at its goal for good before
  t + 1) and ``l_b ≤ t`` (b is at its goal for good from t on, so every other agent is forbidden
  there at every time ≥ t). The two children split the solutions in two, so CBS stays optimal,
  and one split settles what vertex constraints would settle one timestep at a time.
- Meta-agents (MA-CBS, Sharon et al., SoCS 2012): agents of one group are planned together by
  the joint search, so conflicts inside a group never arise and no constraint is ever between
  two members; ``merged`` joins two groups.

A constraint is ``(kind, agent, u, v, t)``: VERTEX forbids ``agent`` in u at t; EDGE forbids the
move u → v arriving at t; LENGTH_GT requires the cost (path length) of ``agent`` to exceed t
(u is its goal); LENGTH_LE requires it to be at most t, and forbids every other agent in u from
t on. A child of the search adds a *branch*: one constraint of ``split``, or the several vertex
constraints of a corridor or rectangle split (``symmetry``).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from planners.mapf.conflicts import Conflict
from planners.mapf.tables import ConstraintTable

VERTEX, EDGE, LENGTH_GT, LENGTH_LE = 0, 1, 2, 3
Constraint = tuple[int, int, int, int, int]

# marks a target conflict ``(t, a, b, u, TARGET)``: a is in b's goal u at t, b parked there
TARGET = -2

# MA-CBS merge threshold B (Sharon et al. 2012 found small values best on small dense maps, large
# ones on open maps): two groups that conflicted more than B times are merged.
MERGE_THRESHOLD = 10
# the largest meta-agent, and the most joint positions (free cells ** members) one may have: the
# joint search grows exponentially with the group, and its replanning under constraints (which
# CBS repeats in many nodes) costs far more than single-agent A* on large maps. So 4 agents are
# merged on maps of up to 26 free cells, 3 up to 79, 2 up to 707 (a 32 x 32 maze, not a 32 x 32
# random map with 10 % obstacles, where merging made CBS slower on the benchmark)
MAX_GROUP = 4
MAX_JOINT_STATES = 500_000
# states the first joint search of a merged group may expand before the merge is given up
JOINT_BUDGET = 500_000
# states a meta-agent's replanning under constraints may expand before its group is merged with
# the group it conflicts with instead (where that merge is allowed): proving that a group has
# no plan under many constraints can cost far more than planning the larger group without them
REPLAN_BUDGET = 20_000


def table_for(n: int, constraints: Iterable[Constraint], agent: int) -> ConstraintTable:
    """The low-level table of ``agent`` under a branch's constraints."""
    table = ConstraintTable(n)
    for kind, who, u, v, t in constraints:
        if kind == LENGTH_LE:
            if who == agent:
                table.add_max_finish(t)
            else:
                table.add_parked(u, t)
        elif who != agent:
            continue
        elif kind == VERTEX:
            table.add_vertex(u, t)
        elif kind == EDGE:
            table.add_edge(u, v, t)
        else:
            table.add_min_finish(t + 1)
    return table


def as_target(conflict: Conflict, goals: Sequence[int], costs: Sequence[int]) -> Conflict:
    """The conflict as a target conflict ``(t, mover, parked, goal, TARGET)`` where it is one."""
    t, a, b, u, v = conflict
    if v != -1:
        return conflict
    if u == goals[b] and t >= costs[b]:
        return (t, a, b, u, TARGET)
    if u == goals[a] and t >= costs[a]:
        return (t, b, a, u, TARGET)
    return conflict


def split(conflict: Conflict) -> list[Constraint]:
    """The constraints of the two children; each child's agent is ``constraint[1]``."""
    t, a, b, u, v = conflict
    if v == TARGET:
        return [(LENGTH_GT, b, u, -1, t), (LENGTH_LE, b, u, -1, t)]
    if v == -1:
        return [(VERTEX, a, u, -1, t), (VERTEX, b, u, -1, t)]
    return [(EDGE, a, u, v, t), (EDGE, b, v, u, t)]


def violators(constraint: Constraint, pos: np.ndarray) -> list[int]:
    """The agents whose current paths (rows of ``pos``, padded) break ``constraint``."""
    kind, agent, u, _v, t = constraint
    if kind != LENGTH_LE:
        return [agent]
    at = (pos[:, t:] == u).any(axis=1) if t < pos.shape[1] else pos[:, -1] == u
    return [int(i) for i in np.nonzero(at)[0] if i != agent]


def groups_of(group: Sequence[int], agents: Iterable[int]) -> list[list[int]]:
    """The members of every group that one of ``agents`` belongs to (``group[i]``: i's group id)."""
    ids = sorted({group[a] for a in agents})
    return [members(group, gid) for gid in ids]


def members(group: Sequence[int], gid: int) -> list[int]:
    """The agents of group ``gid``."""
    return [i for i, g in enumerate(group) if g == gid]


def merged(group: Sequence[int], a: int, b: int) -> tuple[int, ...]:
    """The group ids after merging the groups of ``a`` and ``b`` (a group's id: least member)."""
    ga, gb = group[a], group[b]
    new = min(ga, gb)
    return tuple(new if g in (ga, gb) else g for g in group)


def may_merge(size: int, free_cells: int) -> bool:
    """Whether a meta-agent of ``size`` agents is allowed on a map of ``free_cells`` cells."""
    return size <= MAX_GROUP and free_cells**size <= MAX_JOINT_STATES
