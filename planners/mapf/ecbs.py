"""Enhanced CBS, ECBS(w) (Barer, Sharon, Stern and Felner, SoCS 2014): bounded-suboptimal MAPF.

Both levels are focal searches. The low level (``focal_astar``) returns a path of cost at most
``w`` times the optimum under the agent's constraints, preferring few collisions with the other
agents, and a lower bound ``f_min``. A high-level node's lower bound ``LB`` is the sum of its
agents' bounds; the high level expands, among the nodes with ``SOC ≤ w · min LB``, the one with the
fewest conflicts. The returned SOC is therefore at most ``w`` times the optimal SOC.

Conflicts are split as in ``cbs``: target conflicts on the parked agent's path length (target
reasoning, Li et al., AIJ 2021; here only between groups that already conflicted more than
``TARGET_AFTER`` times), and two groups of agents that conflicted more than
``MERGE_THRESHOLD`` times are merged into a meta-agent (MA-CBS, Sharon et al., SoCS 2012) and the
search restarts (Boyarski et al., IJCAI 2015), as do two groups whose replanning runs past
``REPLAN_BUDGET`` joint expansions. A meta-agent is planned optimally by the joint search
(``joint``), so its cost is its own lower bound and the bound argument above still holds.

Corridor and rectangle reasoning (Li et al., AIJ 2021; ``symmetry``) split a conflict of two
single agents as in ``cbs``, once the two have conflicted more than ``SYMMETRY_AFTER`` times.
Their splits keep every solution in one child (neither needs the paths to be optimal: the
rectangle only needs Manhattan-optimal stretches from the starts, the corridor lower bounds on
arrival times), so each node's lower bound stays a lower bound on the solutions below it, and
the bound ``SOC ≤ w · optimum`` holds.
"""

from __future__ import annotations

from collections.abc import Sequence
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
from planners.mapf.low_level import SearchStats, focal_astar
from planners.mapf.model import InfeasibleInstanceError, path_cost
from planners.mapf.symmetry import Branch, corridor_branches, rectangle_branches
from planners.mapf.tables import ConflictAvoidanceTable, ConstraintTable

# ECBS splits a target conflict on path lengths only once its two groups have conflicted this
# many times: its focal search, guided by conflict counts, does better with the plain vertex split
# on open maps (gen-shelves, k = 170: 0.7 s instead of a timeout), and the length split is
# what settles the agents that keep meeting at a parked agent's goal
TARGET_AFTER = 2
# the same holds for corridor and rectangle splits: always taking them made ECBS time out on
# gen-random-20pct at k = 160 (0.7 s of CPU when they wait for the third conflict of a pair)
SYMMETRY_AFTER = 2


class _Node:
    __slots__ = (
        "branch",
        "conflicts",
        "costs",
        "done",
        "lb",
        "lbs",
        "parent",
        "paths",
        "soc",
    )

    def __init__(
        self,
        parent: _Node | None,
        branch: Branch,
        paths: list[list[int]],
        costs: list[int],
        lbs: list[int],
    ) -> None:
        self.parent = parent
        self.branch = branch
        self.paths = paths
        self.costs = costs
        self.lbs = lbs
        self.soc = sum(costs)
        self.lb = sum(lbs)
        self.conflicts: list[Conflict] = []
        self.done = False


class _Restart(Exception):
    """Two groups were merged: the search starts again from a new root."""


def ecbs(
    graph: GridGraph,
    starts: Sequence[int],
    goals: Sequence[int],
    w: float,
    deadline: Deadline,
    stats: SearchStats,
    merge_threshold: int = MERGE_THRESHOLD,
) -> tuple[list[list[int]], int]:
    """Paths with SOC ≤ w · optimum, and the lower bound that proves it; raises SearchTimeout."""
    if w < 1.0:
        raise ValueError(f"w must be ≥ 1, got {w}")
    search = _Ecbs(graph, starts, goals, w, deadline, stats, merge_threshold)
    while True:
        try:
            return search.run()
        except _Restart:
            continue


class _Ecbs:
    def __init__(
        self,
        graph: GridGraph,
        starts: Sequence[int],
        goals: Sequence[int],
        w: float,
        deadline: Deadline,
        stats: SearchStats,
        merge_threshold: int,
    ) -> None:
        self.graph = graph
        self.starts = list(starts)
        self.goals = list(goals)
        self.w = w
        self.deadline = deadline
        self.stats = stats
        self.merge_threshold = merge_threshold
        self.k = len(self.starts)
        self.group: tuple[int, ...] = tuple(range(self.k))
        self._conflict_counts: dict[tuple[frozenset[int], frozenset[int]], int] = {}
        self._too_big: set[frozenset[int]] = set()
        self._free_cells = int(graph.free.sum())
        self._joint_plans: dict[frozenset[int], list[list[int]]] = {}
        graph.precompute(self.goals)

    def run(self) -> tuple[list[list[int]], int]:
        w = self.w
        root = self._root()
        counter = 0
        open_heap: list[tuple[int, int, _Node]] = []
        focal: list[tuple[int, int, int, _Node]] = []
        waiting: list[tuple[int, int, _Node]] = []
        threshold = w * root.lb + 1e-9

        def push(node: _Node) -> None:
            nonlocal counter
            counter += 1
            heappush(open_heap, (node.lb, counter, node))
            if node.soc <= threshold:
                heappush(focal, (len(node.conflicts), node.soc, counter, node))
            else:
                heappush(waiting, (node.soc, counter, node))

        push(root)
        while True:
            self.deadline.check()
            while open_heap and open_heap[0][2].done:
                heappop(open_heap)
            if not open_heap:
                raise InfeasibleInstanceError("no solution: ECBS exhausted its constraint tree")
            bound = w * open_heap[0][0] + 1e-9
            if bound > threshold:
                threshold = bound
                while waiting and waiting[0][0] <= threshold:
                    soc, c, node = heappop(waiting)
                    heappush(focal, (len(node.conflicts), soc, c, node))
            # the node at the top of OPEN has SOC ≤ w · LB, so FOCAL is never empty here
            while focal[0][3].done:
                heappop(focal)
            node = heappop(focal)[3]
            node.done = True
            if not node.conflicts:
                return node.paths, open_heap[0][0]
            self.stats.high += 1
            conflict = min(node.conflicts)
            a, b = conflict[1], conflict[2]
            count = self._count(a, b)
            if self.merge_threshold and count > self.merge_threshold:
                self._merge(node, a, b)
            if count > TARGET_AFTER:
                conflict = as_target(conflict, self.goals, node.costs)
            pos = positions(node.paths)
            symmetric = self._symmetric(node, conflict, pos) if count > SYMMETRY_AFTER else None
            for branch in symmetric or [(c,) for c in split(conflict)]:
                child = _Node(node, branch, list(node.paths), list(node.costs), list(node.lbs))
                first = branch[0]
                agents = violators(first, pos) if first[0] == LENGTH_LE else [first[1]]
                budget = REPLAN_BUDGET if self._mergeable(a, b) is not None else None
                try:
                    changed = self._replan(child, agents, pos, budget)
                except JointSearchLimit:
                    self._merge(node, a, b)
                    changed = self._replan(child, agents, pos, None)
                if changed is None:
                    continue
                self._update_conflicts(child, node.conflicts, changed, pos)
                push(child)

    @staticmethod
    def _constraints(node: _Node) -> list[Constraint]:
        out: list[Constraint] = []
        anc: _Node | None = node
        while anc is not None:
            out.extend(anc.branch)
            anc = anc.parent
        return out

    def _symmetric(
        self, node: _Node, conflict: Conflict, pos: np.ndarray
    ) -> tuple[Branch, ...] | None:
        """The corridor or rectangle split of a conflict between two single agents, if any."""
        t, a, b, u, v = conflict
        if v == TARGET or self.group.count(self.group[a]) + self.group.count(self.group[b]) > 2:
            return None
        n = self.graph.num_cells
        constraints = self._constraints(node)
        tables = (table_for(n, constraints, a), table_for(n, constraints, b))
        found = corridor_branches(self.graph, pos, conflict, tables, self.deadline)
        if found is None and v == -1:
            found = rectangle_branches(self.graph, pos, t, a, b, u)
        return found

    def _count(self, a: int, b: int) -> int:
        """Count a conflict between the groups of a and b; how many they have had."""
        ga = frozenset(members(self.group, self.group[a]))
        gb = frozenset(members(self.group, self.group[b]))
        key = (ga, gb) if min(ga) < min(gb) else (gb, ga)
        count = self._conflict_counts.get(key, 0) + 1
        self._conflict_counts[key] = count
        return count

    def _mergeable(self, a: int, b: int) -> frozenset[int] | None:
        """The agents of a's and b's groups together, if they may be merged."""
        if not self.merge_threshold:
            return None
        both = frozenset(members(self.group, self.group[a]) + members(self.group, self.group[b]))
        ok = may_merge(len(both), self._free_cells) and both not in self._too_big
        return both if ok else None

    def _merge(self, node: _Node, a: int, b: int) -> None:
        """Merge the groups of a and b and restart (raises _Restart), unless the merged group
        is too large or its joint search exceeds ``JOINT_BUDGET`` (then nothing happens)."""
        both = self._mergeable(a, b)
        if both is None:
            return
        n = self.graph.num_cells
        agents = sorted(both)
        lengths = [len(p) for p in node.paths]
        cat = ConflictAvoidanceTable.from_positions(n, positions(node.paths), lengths, agents)
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
        lbs = [0] * self.k
        planned: list[int] = []
        for gid in sorted(set(self.group)):
            agents = members(self.group, gid)
            if len(agents) > 1:
                for i, path in zip(agents, self._joint_plans[frozenset(agents)], strict=True):
                    paths[i] = path
                    lbs[i] = path_cost(path)
            else:
                found = focal_astar(
                    self.graph,
                    self.starts[gid],
                    self.goals[gid],
                    ConstraintTable(n),
                    ConflictAvoidanceTable.from_paths(n, [paths[i] for i in planned]),
                    self.w,
                    self.deadline,
                    self.stats,
                )
                if found is None:
                    raise RuntimeError("an agent has no path although its goal is reachable")
                paths[gid], lbs[gid] = found
            planned.extend(agents)
        root = _Node(None, (), paths, [path_cost(p) for p in paths], lbs)
        root.conflicts = all_conflicts(paths)
        return root

    def _replan(
        self, node: _Node, agents: Sequence[int], pos: np.ndarray, budget: int | None
    ) -> list[int] | None:
        """Replan the groups of ``agents`` under the node's constraints; the agents replanned,
        or None if a group has no plan (JointSearchLimit past ``budget`` joint expansions)."""
        n = self.graph.num_cells
        lengths = [len(p) for p in node.paths]
        constraints = self._constraints(node)
        changed: list[int] = []
        for group in groups_of(self.group, agents):
            cat = ConflictAvoidanceTable.from_positions(n, pos, lengths, group)
            tables = [table_for(n, constraints, i) for i in group]
            if len(group) == 1:
                agent = group[0]
                found = focal_astar(
                    self.graph,
                    self.starts[agent],
                    self.goals[agent],
                    tables[0],
                    cat,
                    self.w,
                    self.deadline,
                    self.stats,
                )
                if found is None:
                    return None
                path, f_min = found
                node.paths[agent] = path
                node.costs[agent] = path_cost(path)
                node.lbs[agent] = max(node.lbs[agent], f_min)
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
                    node.costs[i] = node.lbs[i] = path_cost(path)
            changed.extend(group)
        node.soc = sum(node.costs)
        node.lb = sum(node.lbs)
        return changed

    def _update_conflicts(
        self, node: _Node, inherited: list[Conflict], changed: list[int], pos: np.ndarray
    ) -> None:
        moved = set(changed)
        kept = [c for c in inherited if c[1] not in moved and c[2] not in moved]
        if len(changed) > 1:
            pos = positions(node.paths)
        done: set[int] = set()
        new: list[Conflict] = []
        for agent in changed:
            new.extend(c for c in conflicts_of(agent, node.paths[agent], pos) if c[2] not in done)
            done.add(agent)
        node.conflicts = kept + new
