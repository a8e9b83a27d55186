"""Conflict-Based Search (Sharon et al., AIJ 2015) with the ICBS improvements, target reasoning and
meta-agents, optimal for SOC.

- Conflict prioritization (Boyarski et al., IJCAI 2015): conflicts are classified with MDDs as
  cardinal (splitting raises both children's cost), semi-cardinal (one child) or non-cardinal;
  the high level splits cardinal conflicts first, then semi-cardinal, then the earliest.
- Bypass (Boyarski et al., SoCS 2015): when a child found paths of the same cost with fewer
  conflicts, the parent takes them and is expanded again instead of branching.
- CG heuristic (Felner et al., ICAPS 2018): each cardinal conflict forces one of its two agents
  to cost one more, so the minimum vertex cover of the graph of cardinally conflicting agents is
  an admissible high-level heuristic; the high level orders nodes by ``SOC + h``.
- Target reasoning (Li et al., AIJ 2021): a conflict with an agent parked at its goal splits on
  that agent's path length (``constraints``); for the parked agent it is always cardinal.
- Corridor and rectangle reasoning (Li et al., "Pairwise symmetry reasoning for multi-agent path
  finding search", AIJ 2021, sections 4 and 5; ``symmetry``): a conflict of two single agents
  inside a one-lane corridor splits on range constraints at the corridor's ends, a vertex
  conflict of two agents crossing an open area Manhattan-optimally on barrier constraints along
  two sides of the rectangle they cross. Each split keeps every solution in one child, so CBS
  stays optimal; their cardinality comes from the MDDs (``mdd.mdd_blocks``). A corridor split
  replaces the conflict's plain split; a rectangle split does where it is at least as cardinal.
- Meta-agents (MA-CBS, Sharon et al., SoCS 2012): when two groups of agents have conflicted
  more than ``MERGE_THRESHOLD`` times in the search (MA-CBS's conflict matrix), they are merged
  into one meta-agent (at most ``MAX_GROUP`` agents, and fewer on large maps, see
  ``constraints.may_merge``), planned by an optimal joint A* with
  operator decomposition (``joint``) under its members' constraints, and the search restarts
  from a new root with the merged group (merge & restart, Boyarski et al., IJCAI 2015). Every
  run is a complete CBS over a partition of the agents, so optimality is kept; agents that
  block each other in a dead end are solved jointly in milliseconds instead of being split
  forever. Two groups are also merged when a meta-agent's replanning under constraints runs
  past ``REPLAN_BUDGET`` joint expansions. A merge whose first joint search exceeds
  ``JOINT_BUDGET`` expansions is given up, and that pair is split as before.
- The low level is space-time A* that breaks ties toward fewer collisions with the other agents'
  paths (a conflict-avoidance table), and the high level toward fewer conflicts.

Everything is ordered by tuples ending in a creation counter, so the output is deterministic.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from heapq import heappop, heappush

import numpy as np

from planners.mapf.conflicts import Conflict, all_conflicts, conflicts_of, positions
from planners.mapf.constraints import (
    JOINT_BUDGET,
    LENGTH_LE,
    MERGE_THRESHOLD,
    REPLAN_BUDGET,
    TARGET,
    Constraint,
    as_target,
    groups_of,
    may_merge,
    members,
    merged,
    split,
    table_for,
    violators,
)
from planners.mapf.deadline import Deadline
from planners.mapf.grid_graph import GridGraph
from planners.mapf.joint import JointSearchLimit, group_plan, joint_astar
from planners.mapf.low_level import SearchStats, space_time_astar
from planners.mapf.mdd import mdd_blocks, mdd_singletons
from planners.mapf.model import InfeasibleInstanceError, path_cost
from planners.mapf.symmetry import Branch, corridor_branches, rectangle_branches
from planners.mapf.tables import ConflictAvoidanceTable, ConstraintTable
from planners.mapf.vertex_cover import min_vertex_cover

CARDINAL, SEMI_CARDINAL, NON_CARDINAL = 0, 1, 2

# (class, t, a, b, u, v, branches): a conflict with its cardinality class first, so min() picks
# the best; v is -1 for a vertex conflict, TARGET for a target conflict (a in b's goal u, b parked
# there); branches: the two children's constraints of a corridor or rectangle split, else ()
Classified = tuple[int, int, int, int, int, int, tuple[Branch, ...]]


@dataclass(frozen=True)
class CbsOptions:
    """Which improvements to use; all off gives the plain CBS of Sharon et al. (baseline).

    ``merge_threshold`` is MA-CBS's B (0: never merge).
    """

    cardinal: bool = True
    bypass: bool = True
    heuristic: str = "cg"
    avoidance_table: bool = True
    target: bool = True
    corridor: bool = True
    rectangle: bool = True
    merge_threshold: int = MERGE_THRESHOLD

    def __post_init__(self) -> None:
        if self.heuristic not in ("none", "cg"):
            raise ValueError(f"heuristic must be 'none' or 'cg', got {self.heuristic!r}")
        if self.heuristic == "cg" and not self.cardinal:
            raise ValueError("the CG heuristic needs cardinal conflict classification")
        if (self.corridor or self.rectangle) and not self.cardinal:
            raise ValueError("corridor and rectangle reasoning need cardinal classification")
        if self.merge_threshold < 0:
            raise ValueError(f"merge_threshold must be ≥ 0, got {self.merge_threshold}")


PLAIN_CBS = CbsOptions(
    cardinal=False,
    bypass=False,
    heuristic="none",
    avoidance_table=False,
    target=False,
    corridor=False,
    rectangle=False,
    merge_threshold=0,
)


class _Node:
    __slots__ = ("branch", "conflicts", "costs", "h", "mdds", "parent", "paths", "soc")

    def __init__(
        self,
        parent: _Node | None,
        branch: Branch,
        paths: list[list[int]],
        costs: list[int],
        mdds: dict[int, tuple[int, ...]],
    ) -> None:
        self.parent = parent
        self.branch = branch
        self.paths = paths
        self.costs = costs
        self.soc = sum(costs)
        self.mdds = mdds
        self.conflicts: list[Classified] = []
        self.h = 0


class _Restart(Exception):
    """Two groups were merged: the search starts again from a new root (ICBS's merge & restart)."""


class ConflictBasedSearch:
    """One CBS run on int cells; ``run()`` returns the paths or raises SearchTimeout."""

    def __init__(
        self,
        graph: GridGraph,
        starts: Sequence[int],
        goals: Sequence[int],
        options: CbsOptions,
        deadline: Deadline,
        stats: SearchStats,
    ) -> None:
        self.graph = graph
        self.starts = list(starts)
        self.goals = list(goals)
        self.options = options
        self.deadline = deadline
        self.stats = stats
        self.k = len(self.starts)
        self.group: tuple[int, ...] = tuple(range(self.k))
        self._counter = 0
        self._conflict_counts: dict[tuple[frozenset[int], frozenset[int]], int] = {}
        self._too_big: set[frozenset[int]] = set()
        self._free_cells = int(graph.free.sum())
        self._joint_plans: dict[frozenset[int], list[list[int]]] = {}
        self._symmetric = options.corridor or options.rectangle
        graph.precompute(self.goals)

    def run(self) -> tuple[list[list[int]], int]:
        """Optimal paths and the root lower bound (SOC of the individually optimal paths)."""
        first_bound: int | None = None
        while True:
            root = self._root()
            if first_bound is None:
                first_bound = root.soc
            try:
                return self._search(root), first_bound
            except _Restart:
                continue

    def _search(self, root: _Node) -> list[list[int]]:
        open_list: list[tuple[int, int, int, _Node]] = []
        self._push(open_list, root)
        while open_list:
            self.deadline.check()
            node = heappop(open_list)[3]
            if not node.conflicts:
                return node.paths
            self.stats.high += 1
            conflict = min(node.conflicts)
            a, b = conflict[2], conflict[3]
            if self._count(a, b):
                self._merge(node, a, b)
            pos = positions(node.paths)
            children = []
            for branch in conflict[6] or [(c,) for c in split(conflict[1:6])]:
                try:
                    child = self._child(node, branch, pos, self._replan_budget(a, b))
                except JointSearchLimit:
                    self._merge(node, a, b)
                    child = self._child(node, branch, pos, None)
                if child is None:
                    continue
                if (
                    self.options.bypass
                    and conflict[0] != CARDINAL
                    and child.soc == node.soc
                    and len(child.conflicts) < len(node.conflicts)
                ):
                    self._adopt(node, child, pos)
                    children = [node]
                    break
                children.append(child)
            for child in children:
                self._push(open_list, child)
        raise InfeasibleInstanceError("no solution: CBS exhausted its constraint tree")

    def _push(self, open_list: list, node: _Node) -> None:
        self._counter += 1
        heappush(open_list, (node.soc + node.h, len(node.conflicts), self._counter, node))

    def _count(self, a: int, b: int) -> bool:
        """Count a conflict between the groups of a and b: whether they should merge now."""
        threshold = self.options.merge_threshold
        if not threshold:
            return False
        ga = frozenset(members(self.group, self.group[a]))
        gb = frozenset(members(self.group, self.group[b]))
        key = (ga, gb) if min(ga) < min(gb) else (gb, ga)
        count = self._conflict_counts.get(key, 0) + 1
        self._conflict_counts[key] = count
        return count > threshold

    def _mergeable(self, a: int, b: int) -> frozenset[int] | None:
        """The agents of a's and b's groups together, if they may be merged."""
        if not self.options.merge_threshold:
            return None
        both = frozenset(members(self.group, self.group[a]) + members(self.group, self.group[b]))
        ok = may_merge(len(both), self._free_cells) and both not in self._too_big
        return both if ok else None

    def _replan_budget(self, a: int, b: int) -> int | None:
        return REPLAN_BUDGET if self._mergeable(a, b) is not None else None

    def _merge(self, node: _Node, a: int, b: int) -> None:
        """Merge the groups of a and b and restart (raises _Restart), unless the merged group
        is too large or its joint search exceeds ``JOINT_BUDGET`` (then nothing happens)."""
        both = self._mergeable(a, b)
        if both is None:
            return
        n = self.graph.num_cells
        lengths = [len(p) for p in node.paths]
        cat = (
            ConflictAvoidanceTable.from_positions(n, positions(node.paths), lengths, sorted(both))
            if self.options.avoidance_table
            else None
        )
        agents = sorted(both)
        try:
            paths = group_plan(
                self.graph,
                self.starts,
                self.goals,
                agents,
                cat,
                self.deadline,
                self.stats,
                JOINT_BUDGET,
            )
        except JointSearchLimit:
            self._too_big.add(both)
            return
        self._joint_plans[both] = paths
        self.group = merged(self.group, a, b)
        raise _Restart

    def _root(self) -> _Node:
        n = self.graph.num_cells
        paths: list[list[int]] = [[] for _ in range(self.k)]
        planned: list[int] = []
        for gid in sorted(set(self.group)):
            agents = members(self.group, gid)
            if len(agents) > 1:
                found = self._joint_plans[frozenset(agents)]
            else:
                cat = (
                    ConflictAvoidanceTable.from_paths(n, [paths[i] for i in planned])
                    if self.options.avoidance_table
                    else None
                )
                path = space_time_astar(
                    self.graph,
                    self.starts[gid],
                    self.goals[gid],
                    ConstraintTable(n),
                    cat,
                    self.deadline,
                    self.stats,
                )
                if path is None:
                    raise RuntimeError("an agent has no path although its goal is reachable")
                found = [path]
            for i, path in zip(agents, found, strict=True):
                paths[i] = path
                planned.append(i)
        root = _Node(None, (), paths, [path_cost(p) for p in paths], {})
        pos = positions(paths)
        root.conflicts = [self._classify(root, c, pos) for c in all_conflicts(paths)]
        root.h = self._heuristic(root)
        return root

    @staticmethod
    def _constraints(node: _Node) -> list[Constraint]:
        out: list[Constraint] = []
        while node.parent is not None:
            out.extend(node.branch)
            node = node.parent
        return out

    def _table(self, node: _Node, agent: int) -> ConstraintTable:
        return table_for(self.graph.num_cells, self._constraints(node), agent)

    def _child(
        self, node: _Node, branch: Branch, pos: np.ndarray, budget: int | None
    ) -> _Node | None:
        child = _Node(node, branch, list(node.paths), list(node.costs), dict(node.mdds))
        first = branch[0]
        agents = violators(first, pos) if first[0] == LENGTH_LE else [first[1]]
        changed = self._replan(child, agents, pos, budget)
        if changed is None:
            return None
        self._update_conflicts(child, node.conflicts, changed, pos if len(changed) == 1 else None)
        return child

    def _replan(
        self, node: _Node, agents: Sequence[int], pos: np.ndarray, budget: int | None
    ) -> list[int] | None:
        """Replan the groups of ``agents`` in ``node``; the agents replanned, or None if one of
        those groups has no plan. Single agents use space-time A*, groups the joint search
        (raises JointSearchLimit past ``budget`` expansions)."""
        n = self.graph.num_cells
        lengths = [len(p) for p in node.paths]
        constraints = self._constraints(node)
        changed: list[int] = []
        for group in groups_of(self.group, agents):
            cat = (
                ConflictAvoidanceTable.from_positions(n, pos, lengths, group)
                if self.options.avoidance_table
                else None
            )
            tables = [table_for(n, constraints, i) for i in group]
            if len(group) == 1:
                path = space_time_astar(
                    self.graph,
                    self.starts[group[0]],
                    self.goals[group[0]],
                    tables[0],
                    cat,
                    self.deadline,
                    self.stats,
                )
                paths = None if path is None else [path]
            else:
                paths = joint_astar(
                    self.graph,
                    [self.starts[i] for i in group],
                    [self.goals[i] for i in group],
                    tables,
                    cat,
                    self.deadline,
                    self.stats,
                    budget,
                )
            if paths is None:
                return None
            for i, path in zip(group, paths, strict=True):
                node.paths[i] = path
                node.costs[i] = path_cost(path)
                node.mdds.pop(i, None)
                changed.append(i)
        node.soc = sum(node.costs)
        return changed

    def _adopt(self, node: _Node, child: _Node, pos: np.ndarray) -> None:
        """Bypass: the node keeps its constraints and cost but takes the child's better paths."""
        old = list(node.conflicts)
        changed = [i for i in range(self.k) if child.paths[i] is not node.paths[i]]
        node.paths = list(node.paths)
        node.costs = list(node.costs)
        for i in changed:
            node.paths[i] = child.paths[i]
            node.costs[i] = child.costs[i]
            node.mdds.pop(i, None)
        self._update_conflicts(node, old, changed, pos if len(changed) == 1 else None)

    def _update_conflicts(
        self,
        node: _Node,
        inherited: list[Classified],
        changed: list[int],
        pos: np.ndarray | None,
    ) -> None:
        """Keep the conflicts not involving ``changed`` agents and find theirs anew (``pos``: the
        parent's positions, usable when only one agent changed)."""
        moved = set(changed)
        kept = [c for c in inherited if c[2] not in moved and c[3] not in moved]
        if pos is None:
            pos = positions(node.paths)
        done: set[int] = set()
        new: list[Conflict] = []
        for agent in changed:
            new.extend(c for c in conflicts_of(agent, node.paths[agent], pos) if c[2] not in done)
            done.add(agent)
        now = positions(node.paths) if new and self._symmetric else pos
        node.conflicts = kept + [self._classify(node, c, now) for c in new]
        node.h = self._heuristic(node)

    def _single(self, agent: int) -> bool:
        return self.group.count(self.group[agent]) == 1

    def _mdd(self, node: _Node, agent: int) -> tuple[int, ...]:
        singles = node.mdds.get(agent)
        if singles is None:
            singles = mdd_singletons(
                self.graph,
                self.starts[agent],
                self.goals[agent],
                node.costs[agent],
                self._table(node, agent),
            )
            node.mdds[agent] = singles
        return singles

    def _cardinal_for(self, node: _Node, agent: int, t: int, frm: int, to: int) -> bool:
        """Whether forbidding the agent's part of the conflict raises its cost (a member of a
        meta-agent: never claimed, the group may trade cost between its members)."""
        if not self._single(agent):
            return False
        cost = node.costs[agent]
        if to == -1:
            return t >= cost or self._mdd(node, agent)[t] == frm
        singles = self._mdd(node, agent)
        return t <= cost and singles[t - 1] == frm and singles[t] == to

    def _classify(self, node: _Node, conflict: Conflict, pos: np.ndarray) -> Classified:
        """The conflict with its cardinality class and, where corridor or rectangle reasoning
        applies, the branches of its symmetric split (``pos``: the node's padded paths)."""
        if self.options.target:
            conflict = as_target(conflict, self.goals, node.costs)
        t, a, b, u, v = conflict
        if not self.options.cardinal:
            return (NON_CARDINAL, t, a, b, u, v, ())
        if v == TARGET:
            # l_b > t raises the parked agent's cost; l_b ≤ t bars the mover from u from t on
            ca = t <= node.costs[a] and self._cardinal_for(node, a, t, u, -1)
            cb = self._single(b)
            return (2 - ca - cb, t, a, b, u, v, ())
        ca = self._cardinal_for(node, a, t, u, v)
        cb = (
            self._cardinal_for(node, b, t, u, -1)
            if v == -1
            else self._cardinal_for(node, b, t, v, u)
        )
        plain = 2 - ca - cb
        if self._symmetric and self._single(a) and self._single(b):
            if self.options.corridor:
                tables = (self._table(node, a), self._table(node, b))
                found = corridor_branches(self.graph, pos, conflict, tables, self.deadline)
                if found is not None:
                    return (self._branch_class(node, a, b, found), t, a, b, u, v, found)
            if self.options.rectangle and v == -1 and plain != CARDINAL:
                found = rectangle_branches(self.graph, pos, t, a, b, u)
                if found is not None:
                    cls = self._branch_class(node, a, b, found)
                    if cls <= plain:
                        return (cls, t, a, b, u, v, found)
        return (plain, t, a, b, u, v, ())

    def _branch_class(self, node: _Node, a: int, b: int, branches: tuple[Branch, ...]) -> int:
        """Cardinality class of a symmetric split: how many of its two branches leave no path of
        the agent's current cost (checked on the MDD, so the CG heuristic stays admissible)."""
        raised = 0
        for agent, branch in zip((a, b), branches, strict=True):
            forbidden = {(c[2], c[4]) for c in branch}
            raised += mdd_blocks(
                self.graph,
                self.starts[agent],
                self.goals[agent],
                node.costs[agent],
                self._table(node, agent),
                forbidden,
            )
        return 2 - raised

    def _heuristic(self, node: _Node) -> int:
        if self.options.heuristic == "none":
            return 0
        edges = {(c[2], c[3]) if c[2] < c[3] else (c[3], c[2]) for c in node.conflicts if c[0] == 0}
        return min_vertex_cover(edges)
