"""Conflict-Based Search (Sharon et al., AIJ 2015) with the ICBS improvements, optimal for SOC.

- Conflict prioritization (Boyarski et al., IJCAI 2015): conflicts are classified with MDDs as
  cardinal (splitting raises both children's cost), semi-cardinal (one child) or non-cardinal;
  the high level splits cardinal conflicts first, then semi-cardinal, then the earliest.
- Bypass (Boyarski et al., SoCS 2015): when a child found a path of the same cost with fewer
  conflicts, the parent takes that path and is expanded again instead of branching.
- CG heuristic (Felner et al., ICAPS 2018): each cardinal conflict forces one of its two agents
  to cost one more, so the minimum vertex cover of the graph of cardinally conflicting agents is
  an admissible high-level heuristic; the high level orders nodes by ``SOC + h``.
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
from planners.mapf.deadline import Deadline
from planners.mapf.grid_graph import GridGraph
from planners.mapf.low_level import SearchStats, space_time_astar
from planners.mapf.mdd import mdd_singletons
from planners.mapf.model import InfeasibleInstanceError, path_cost
from planners.mapf.tables import ConflictAvoidanceTable, ConstraintTable
from planners.mapf.vertex_cover import min_vertex_cover

CARDINAL, SEMI_CARDINAL, NON_CARDINAL = 0, 1, 2

# A constraint forbids its agent (u, -1, t): being in u at t; (u, v, t): moving u → v arriving t.
Constraint = tuple[int, int, int]
# (class, t, a, b, u, v): a conflict with its cardinality class first, so min() picks the best.
Classified = tuple[int, int, int, int, int, int]


@dataclass(frozen=True)
class CbsOptions:
    """Which ICBS improvements to use; all off gives the plain CBS of Sharon et al. (baseline)."""

    cardinal: bool = True
    bypass: bool = True
    heuristic: str = "cg"
    avoidance_table: bool = True

    def __post_init__(self) -> None:
        if self.heuristic not in ("none", "cg"):
            raise ValueError(f"heuristic must be 'none' or 'cg', got {self.heuristic!r}")
        if self.heuristic == "cg" and not self.cardinal:
            raise ValueError("the CG heuristic needs cardinal conflict classification")


PLAIN_CBS = CbsOptions(cardinal=False, bypass=False, heuristic="none", avoidance_table=False)


class _Node:
    __slots__ = ("agent", "conflicts", "constraint", "costs", "h", "mdds", "parent", "paths", "soc")

    def __init__(
        self,
        parent: _Node | None,
        agent: int,
        constraint: Constraint | None,
        paths: list[list[int]],
        costs: list[int],
        mdds: dict[int, tuple[int, ...]],
    ) -> None:
        self.parent = parent
        self.agent = agent
        self.constraint = constraint
        self.paths = paths
        self.costs = costs
        self.soc = sum(costs)
        self.mdds = mdds
        self.conflicts: list[Classified] = []
        self.h = 0


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
        self._counter = 0
        graph.precompute(self.goals)

    def run(self) -> tuple[list[list[int]], int]:
        """Optimal paths and the root lower bound (SOC of the individually optimal paths)."""
        root = self._root()
        if root is None:
            raise RuntimeError("an agent has no path although its goal is reachable")
        open_list: list[tuple[int, int, int, _Node]] = []
        self._push(open_list, root)
        while open_list:
            self.deadline.check()
            node = heappop(open_list)[3]
            if not node.conflicts:
                return node.paths, root.soc
            self.stats.high += 1
            conflict = min(node.conflicts)
            pos = positions(node.paths)
            children = []
            for agent, constraint in self._split(conflict):
                child = self._child(node, agent, constraint, pos)
                if child is None:
                    continue
                if (
                    self.options.bypass
                    and conflict[0] != CARDINAL
                    and child.soc == node.soc
                    and len(child.conflicts) < len(node.conflicts)
                ):
                    self._adopt(node, agent, child.paths[agent], pos)
                    children = [node]
                    break
                children.append(child)
            for child in children:
                self._push(open_list, child)
        raise InfeasibleInstanceError("no solution: CBS exhausted its constraint tree")

    def _push(self, open_list: list, node: _Node) -> None:
        self._counter += 1
        heappush(open_list, (node.soc + node.h, len(node.conflicts), self._counter, node))

    def _root(self) -> _Node | None:
        n = self.graph.num_cells
        paths: list[list[int]] = []
        for i in range(self.k):
            cat = (
                ConflictAvoidanceTable.from_paths(n, paths)
                if self.options.avoidance_table
                else None
            )
            path = space_time_astar(
                self.graph,
                self.starts[i],
                self.goals[i],
                ConstraintTable(n),
                cat,
                self.deadline,
                self.stats,
            )
            if path is None:
                return None
            paths.append(path)
        root = _Node(None, -1, None, paths, [path_cost(p) for p in paths], {})
        root.conflicts = [self._classify(root, c) for c in all_conflicts(paths)]
        root.h = self._heuristic(root)
        return root

    @staticmethod
    def _split(conflict: Classified) -> list[tuple[int, Constraint]]:
        _, t, a, b, u, v = conflict
        if v == -1:
            return [(a, (u, -1, t)), (b, (u, -1, t))]
        return [(a, (u, v, t)), (b, (v, u, t))]

    def _table(self, node: _Node, agent: int) -> ConstraintTable:
        table = ConstraintTable(self.graph.num_cells)
        while node.parent is not None:
            if node.agent == agent:
                u, v, t = node.constraint  # type: ignore[misc]
                if v == -1:
                    table.add_vertex(u, t)
                else:
                    table.add_edge(u, v, t)
            node = node.parent
        return table

    def _child(
        self, node: _Node, agent: int, constraint: Constraint, pos: np.ndarray
    ) -> _Node | None:
        child = _Node(node, agent, constraint, list(node.paths), list(node.costs), dict(node.mdds))
        child.mdds.pop(agent, None)
        cat = (
            ConflictAvoidanceTable.from_positions(
                self.graph.num_cells, pos, [len(p) for p in node.paths], agent
            )
            if self.options.avoidance_table
            else None
        )
        path = space_time_astar(
            self.graph,
            self.starts[agent],
            self.goals[agent],
            self._table(child, agent),
            cat,
            self.deadline,
            self.stats,
        )
        if path is None:
            return None
        child.paths[agent] = path
        child.costs[agent] = path_cost(path)
        child.soc = sum(child.costs)
        self._update_conflicts(child, node.conflicts, agent, path, pos)
        return child

    def _adopt(self, node: _Node, agent: int, path: list[int], pos: np.ndarray) -> None:
        """Bypass: the node keeps its constraints and cost but takes the better path."""
        old = list(node.conflicts)
        node.paths = list(node.paths)
        node.paths[agent] = path
        self._update_conflicts(node, old, agent, path, pos)

    def _update_conflicts(
        self,
        node: _Node,
        inherited: list[Classified],
        agent: int,
        path: list[int],
        pos: np.ndarray,
    ) -> None:
        kept = [c for c in inherited if c[2] != agent and c[3] != agent]
        new = [self._classify(node, c) for c in conflicts_of(agent, path, pos)]
        node.conflicts = kept + new
        node.h = self._heuristic(node)

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
        cost = node.costs[agent]
        if to == -1:
            return t >= cost or self._mdd(node, agent)[t] == frm
        singles = self._mdd(node, agent)
        return t <= cost and singles[t - 1] == frm and singles[t] == to

    def _classify(self, node: _Node, conflict: Conflict) -> Classified:
        t, a, b, u, v = conflict
        if not self.options.cardinal:
            return (NON_CARDINAL, t, a, b, u, v)
        ca = self._cardinal_for(node, a, t, u, v)
        cb = (
            self._cardinal_for(node, b, t, u, -1)
            if v == -1
            else self._cardinal_for(node, b, t, v, u)
        )
        return (2 - ca - cb, t, a, b, u, v)

    def _heuristic(self, node: _Node) -> int:
        if self.options.heuristic == "none":
            return 0
        edges = {(c[2], c[3]) if c[2] < c[3] else (c[3], c[2]) for c in node.conflicts if c[0] == 0}
        return min_vertex_cover(edges)
