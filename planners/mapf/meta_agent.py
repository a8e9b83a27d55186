"""The high level that CBS and ECBS share: a constraint tree over groups of agents (meta-agents).

Both searches (``cbs``: Sharon et al., AIJ 2015, with ICBS, Boyarski et al., IJCAI 2015; ``ecbs``:
Barer et al., SoCS 2014) expand a node by splitting one conflict into branches, replanning in
each child the groups of agents the branch's constraints bind (a single agent by its low level, a
meta-agent by the joint search), and finding anew only the replanned agents' conflicts.

Meta-agents (MA-CBS, Sharon et al., SoCS 2012): when two groups of agents have conflicted more
than ``merge_threshold`` times in the search (MA-CBS's conflict matrix), they are merged into one
meta-agent (at most ``MAX_GROUP`` agents, and fewer on large maps, see
``constraints.may_merge``), planned by the optimal joint A* of ``joint`` under its members'
constraints, and the search restarts from a new root with the merged group (merge & restart,
Boyarski et al., IJCAI 2015). Two groups are also merged when a meta-agent's replanning under
constraints runs past ``REPLAN_BUDGET`` joint expansions. A merge whose first joint search exceeds
``JOINT_BUDGET`` expansions is given up, and that pair is split as before.

A subclass gives the node type, the single-agent low level, how new conflicts are classified and
the search over the tree (best-first for CBS, focal for ECBS).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np

from planners.mapf.conflicts import Conflict, all_conflicts, conflicts_of, positions
from planners.mapf.constraints import (
    JOINT_BUDGET,
    LENGTH_LE,
    REPLAN_BUDGET,
    Constraint,
    groups_of,
    may_merge,
    members,
    merged,
    table_for,
    violators,
)
from planners.mapf.deadline import Deadline
from planners.mapf.grid_graph import GridGraph
from planners.mapf.joint import JointSearchLimit, group_plan, joint_astar
from planners.mapf.low_level import SearchStats
from planners.mapf.model import path_cost
from planners.mapf.symmetry import Branch
from planners.mapf.tables import ConflictAvoidanceTable, ConstraintTable

CARDINAL, SEMI_CARDINAL, NON_CARDINAL = 0, 1, 2

# (class, t, a, b, u, v, branches): a conflict with its cardinality class first, so min() picks
# the best; v is -1 for a vertex conflict, TARGET for a target conflict (a in b's goal u, b parked
# there); branches: the two children's constraints of a corridor or rectangle split, else ()
Classified = tuple[int, int, int, int, int, int, tuple[Branch, ...]]


class Restart(Exception):
    """Two groups were merged: the search starts again from a new root (ICBS's merge & restart)."""


class TreeNode:
    """A node of the constraint tree: the branch that made it, its agents' paths and costs, and
    its conflicts. Subclasses add what their search orders nodes by."""

    __slots__ = ("branch", "conflicts", "costs", "parent", "paths", "soc")

    def __init__(
        self, parent: TreeNode | None, branch: Branch, paths: list[list[int]], costs: list[int]
    ) -> None:
        self.parent = parent
        self.branch = branch
        self.paths = paths
        self.costs = costs
        self.soc = sum(costs)
        self.conflicts: list[Classified] = []

    def child(self, branch: Branch) -> TreeNode:
        """A child with this node's paths (to be replanned) under one more branch."""
        raise NotImplementedError

    def constraints(self) -> list[Constraint]:
        """The constraints of every branch from the root down to this node."""
        out: list[Constraint] = []
        node: TreeNode | None = self
        while node is not None:
            out.extend(node.branch)
            node = node.parent
        return out

    def set_single(self, agent: int, path: list[int], bound: int) -> None:
        """A single agent's new path; ``bound``: its low level's lower bound on the cost."""
        self.set_member(agent, path)

    def set_member(self, agent: int, path: list[int]) -> None:
        """A new path of an agent (of a meta-agent, planned optimally)."""
        self.paths[agent] = path
        self.costs[agent] = path_cost(path)

    def settle(self) -> None:
        """Bring the totals up to date after replanning."""
        self.soc = sum(self.costs)


class MetaAgentSearch:
    """One CBS-like run on int cells over a partition of the agents into groups."""

    def __init__(
        self,
        graph: GridGraph,
        starts: Sequence[int],
        goals: Sequence[int],
        deadline: Deadline,
        stats: SearchStats,
        merge_threshold: int,
        avoidance_table: bool,
    ) -> None:
        self.graph = graph
        self.starts = list(starts)
        self.goals = list(goals)
        self.deadline = deadline
        self.stats = stats
        self.merge_threshold = merge_threshold
        self.avoidance_table = avoidance_table
        self.k = len(self.starts)
        self.group: tuple[int, ...] = tuple(range(self.k))
        self.first_root_soc: int | None = None
        self._conflict_counts: dict[tuple[frozenset[int], frozenset[int]], int] = {}
        self._too_big: set[frozenset[int]] = set()
        self._free_cells = int(graph.free.sum())
        self._joint_plans: dict[frozenset[int], list[list[int]]] = {}
        graph.precompute(self.goals)

    def run(self) -> tuple[list[list[int]], int]:
        """The paths and a lower bound on the optimal SOC; raises SearchTimeout at the deadline
        and InfeasibleInstanceError when the constraint tree is exhausted."""
        while True:
            root = self._root()
            try:
                return self._search(root)
            except Restart:
                continue

    def _search(self, root: TreeNode) -> tuple[list[list[int]], int]:
        raise NotImplementedError

    def _low_level(
        self, agent: int, table: ConstraintTable, cat: ConflictAvoidanceTable | None
    ) -> tuple[list[int], int] | None:
        """A single agent's path under ``table`` and a lower bound on its cost, or None."""
        raise NotImplementedError

    def _new_root(self, paths: list[list[int]], bounds: list[int]) -> TreeNode:
        raise NotImplementedError

    def _set_conflicts(
        self, node: TreeNode, kept: list[Classified], new: list[Conflict], pos: np.ndarray
    ) -> None:
        """``node.conflicts``: the ``kept`` ones and the ``new`` ones classified (``pos``: the
        parent's positions where only one agent changed, else the node's)."""
        raise NotImplementedError

    def _single(self, agent: int) -> bool:
        return self.group.count(self.group[agent]) == 1

    def _table(self, node: TreeNode, agent: int) -> ConstraintTable:
        return table_for(self.graph.num_cells, node.constraints(), agent)

    def _avoidance(
        self, pos: np.ndarray, lengths: list[int], exclude: Sequence[int]
    ) -> ConflictAvoidanceTable | None:
        if not self.avoidance_table:
            return None
        return ConflictAvoidanceTable.from_positions(self.graph.num_cells, pos, lengths, exclude)

    def _root(self) -> TreeNode:
        """The root of the current partition: each group planned without constraints, single
        agents in turn avoiding the paths planned before them."""
        n = self.graph.num_cells
        paths: list[list[int]] = [[] for _ in range(self.k)]
        bounds = [0] * self.k
        planned: list[int] = []
        for gid in sorted(set(self.group)):
            agents = members(self.group, gid)
            if len(agents) > 1:
                found = self._joint_plans[frozenset(agents)]
                found_bounds = [path_cost(p) for p in found]
            else:
                cat = (
                    ConflictAvoidanceTable.from_paths(n, [paths[i] for i in planned])
                    if self.avoidance_table
                    else None
                )
                single = self._low_level(gid, ConstraintTable(n), cat)
                if single is None:
                    raise RuntimeError("an agent has no path although its goal is reachable")
                found, found_bounds = [single[0]], [single[1]]
            for i, path, bound in zip(agents, found, found_bounds, strict=True):
                paths[i] = path
                bounds[i] = bound
                planned.append(i)
        root = self._new_root(paths, bounds)
        if self.first_root_soc is None:
            self.first_root_soc = root.soc
        self._set_conflicts(root, [], all_conflicts(paths), positions(paths))
        return root

    def _tally(self, node: TreeNode, a: int, b: int) -> int:
        """Count a conflict between the groups of a and b, and merge them (raises Restart) once
        they have had more than ``merge_threshold``; how many they have had."""
        ga = frozenset(members(self.group, self.group[a]))
        gb = frozenset(members(self.group, self.group[b]))
        key = (ga, gb) if min(ga) < min(gb) else (gb, ga)
        count = self._conflict_counts.get(key, 0) + 1
        self._conflict_counts[key] = count
        if self.merge_threshold and count > self.merge_threshold:
            self._merge(node, a, b)
        return count

    def _mergeable(self, a: int, b: int) -> frozenset[int] | None:
        """The agents of a's and b's groups together, if they may be merged."""
        if not self.merge_threshold:
            return None
        both = frozenset(members(self.group, self.group[a]) + members(self.group, self.group[b]))
        ok = may_merge(len(both), self._free_cells) and both not in self._too_big
        return both if ok else None

    def _merge(self, node: TreeNode, a: int, b: int) -> None:
        """Merge the groups of a and b and restart (raises Restart), unless the merged group
        is too large or its joint search exceeds ``JOINT_BUDGET`` (then nothing happens)."""
        both = self._mergeable(a, b)
        if both is None:
            return
        agents = sorted(both)
        cat = self._avoidance(positions(node.paths), [len(p) for p in node.paths], agents)
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
        raise Restart

    def _children(
        self, node: TreeNode, a: int, b: int, branches: Sequence[Branch], pos: np.ndarray
    ) -> Iterator[TreeNode]:
        """The children of ``node``, one per branch of its conflict between a and b that leaves
        a plan (``pos``: the node's padded paths). A meta-agent whose replanning runs past
        ``REPLAN_BUDGET`` is merged with the other group (raises Restart) where it may be."""
        for branch in branches:
            budget = REPLAN_BUDGET if self._mergeable(a, b) is not None else None
            try:
                child = self._child(node, branch, pos, budget)
            except JointSearchLimit:
                self._merge(node, a, b)
                child = self._child(node, branch, pos, None)
            if child is not None:
                yield child

    def _child(
        self, node: TreeNode, branch: Branch, pos: np.ndarray, budget: int | None
    ) -> TreeNode | None:
        child = node.child(branch)
        first = branch[0]
        agents = violators(first, pos) if first[0] == LENGTH_LE else [first[1]]
        changed = self._replan(child, agents, pos, budget)
        if changed is None:
            return None
        self._update_conflicts(child, node.conflicts, changed, pos if len(changed) == 1 else None)
        return child

    def _replan(
        self, node: TreeNode, agents: Sequence[int], pos: np.ndarray, budget: int | None
    ) -> list[int] | None:
        """Replan the groups of ``agents`` in ``node``; the agents replanned, or None if one of
        those groups has no plan. Single agents use the low level, groups the joint search
        (raises JointSearchLimit past ``budget`` expansions)."""
        n = self.graph.num_cells
        lengths = [len(p) for p in node.paths]
        constraints = node.constraints()
        changed: list[int] = []
        for group in groups_of(self.group, agents):
            cat = self._avoidance(pos, lengths, group)
            tables = [table_for(n, constraints, i) for i in group]
            if len(group) == 1:
                found = self._low_level(group[0], tables[0], cat)
                if found is None:
                    return None
                node.set_single(group[0], *found)
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
                    node.set_member(i, path)
            changed.extend(group)
        node.settle()
        return changed

    def _update_conflicts(
        self,
        node: TreeNode,
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
        self._set_conflicts(node, kept, new, pos)
