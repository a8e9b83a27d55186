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

from planners.mapf.conflicts import Conflict, positions
from planners.mapf.constraints import MERGE_THRESHOLD, TARGET, as_target, split
from planners.mapf.deadline import Deadline
from planners.mapf.grid_graph import GridGraph
from planners.mapf.low_level import SearchStats, focal_astar
from planners.mapf.meta_agent import (
    NON_CARDINAL,
    Classified,
    MetaAgentSearch,
    TreeNode,
)
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


class _Node(TreeNode):
    """An ECBS node: also its agents' lower bounds, their sum, and whether it was expanded."""

    __slots__ = ("done", "lb", "lbs")

    def __init__(
        self,
        parent: _Node | None,
        branch: Branch,
        paths: list[list[int]],
        costs: list[int],
        lbs: list[int],
    ) -> None:
        super().__init__(parent, branch, paths, costs)
        self.lbs = lbs
        self.lb = sum(lbs)
        self.done = False

    def child(self, branch: Branch) -> _Node:
        return _Node(self, branch, list(self.paths), list(self.costs), list(self.lbs))

    def set_single(self, agent: int, path: list[int], bound: int) -> None:
        self.paths[agent] = path
        self.costs[agent] = path_cost(path)
        self.lbs[agent] = max(self.lbs[agent], bound)

    def set_member(self, agent: int, path: list[int]) -> None:
        self.paths[agent] = path
        self.costs[agent] = self.lbs[agent] = path_cost(path)

    def settle(self) -> None:
        self.soc = sum(self.costs)
        self.lb = sum(self.lbs)


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
    return _Ecbs(graph, starts, goals, w, deadline, stats, merge_threshold).run()


class _Ecbs(MetaAgentSearch):
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
        super().__init__(graph, starts, goals, deadline, stats, merge_threshold, True)
        self.w = w

    def _search(self, root: TreeNode) -> tuple[list[list[int]], int]:
        w = self.w
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
            conflict = min(node.conflicts)[1:6]
            a, b = conflict[1], conflict[2]
            count = self._tally(node, a, b)
            if count > TARGET_AFTER:
                conflict = as_target(conflict, self.goals, node.costs)
            pos = positions(node.paths)
            symmetric = self._symmetric(node, conflict, pos) if count > SYMMETRY_AFTER else None
            branches = symmetric or [(c,) for c in split(conflict)]
            for child in self._children(node, a, b, branches, pos):
                push(child)

    def _symmetric(
        self, node: _Node, conflict: Conflict, pos: np.ndarray
    ) -> tuple[Branch, ...] | None:
        """The corridor or rectangle split of a conflict between two single agents, if any."""
        t, a, b, u, v = conflict
        if v == TARGET or not (self._single(a) and self._single(b)):
            return None
        tables = (self._table(node, a), self._table(node, b))
        found = corridor_branches(self.graph, pos, conflict, tables, self.deadline)
        if found is None and v == -1:
            found = rectangle_branches(self.graph, pos, t, a, b, u)
        return found

    def _low_level(
        self, agent: int, table: ConstraintTable, cat: ConflictAvoidanceTable | None
    ) -> tuple[list[int], int] | None:
        assert cat is not None
        return focal_astar(
            self.graph,
            self.starts[agent],
            self.goals[agent],
            table,
            cat,
            self.w,
            self.deadline,
            self.stats,
        )

    def _new_root(self, paths: list[list[int]], bounds: list[int]) -> _Node:
        return _Node(None, (), paths, [path_cost(p) for p in paths], bounds)

    def _set_conflicts(
        self, node: _Node, kept: list[Classified], new: list[Conflict], pos: np.ndarray
    ) -> None:
        node.conflicts = kept + [(NON_CARDINAL, *c, ()) for c in new]
