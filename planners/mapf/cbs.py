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
- Meta-agents (MA-CBS, Sharon et al., SoCS 2012; ``meta_agent``, shared with ECBS): two groups
  of agents that keep conflicting are merged into one meta-agent, planned by an optimal joint A*
  with operator decomposition (``joint``) under its members' constraints, and the search restarts
  from a new root with the merged group (merge & restart, Boyarski et al., IJCAI 2015). Every
  run is a complete CBS over a partition of the agents, so optimality is kept; agents that
  block each other in a dead end are solved jointly in milliseconds instead of being split
  forever.
- The low level is space-time A* that breaks ties toward fewer collisions with the other agents'
  paths (a conflict-avoidance table), and the high level toward fewer conflicts.

Everything is ordered by tuples ending in a creation counter, so the output is deterministic.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from heapq import heappop, heappush

import numpy as np

from planners.mapf.conflicts import Conflict, positions
from planners.mapf.constraints import MERGE_THRESHOLD, TARGET, as_target, split
from planners.mapf.deadline import Deadline
from planners.mapf.grid_graph import GridGraph
from planners.mapf.low_level import SearchStats, space_time_astar
from planners.mapf.mdd import mdd_blocks, mdd_singletons
from planners.mapf.meta_agent import (
    CARDINAL,
    NON_CARDINAL,
    Classified,
    MetaAgentSearch,
    TreeNode,
)
from planners.mapf.model import InfeasibleInstanceError, path_cost
from planners.mapf.symmetry import Branch, corridor_branches, rectangle_branches
from planners.mapf.tables import ConflictAvoidanceTable, ConstraintTable
from planners.mapf.vertex_cover import min_vertex_cover


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


class _Node(TreeNode):
    """A CBS node: also its agents' MDD singletons (computed on demand) and its CG heuristic."""

    __slots__ = ("h", "mdds")

    def __init__(
        self,
        parent: _Node | None,
        branch: Branch,
        paths: list[list[int]],
        costs: list[int],
        mdds: dict[int, tuple[int, ...]],
    ) -> None:
        super().__init__(parent, branch, paths, costs)
        self.mdds = mdds
        self.h = 0

    def child(self, branch: Branch) -> _Node:
        return _Node(self, branch, list(self.paths), list(self.costs), dict(self.mdds))

    def set_member(self, agent: int, path: list[int]) -> None:
        super().set_member(agent, path)
        self.mdds.pop(agent, None)


class ConflictBasedSearch(MetaAgentSearch):
    """One CBS run on int cells; ``run()`` returns the optimal paths and the first root's SOC
    (a lower bound), or raises SearchTimeout."""

    def __init__(
        self,
        graph: GridGraph,
        starts: Sequence[int],
        goals: Sequence[int],
        options: CbsOptions,
        deadline: Deadline,
        stats: SearchStats,
    ) -> None:
        super().__init__(
            graph,
            starts,
            goals,
            deadline,
            stats,
            options.merge_threshold,
            options.avoidance_table,
        )
        self.options = options
        self._counter = 0
        self._symmetric = options.corridor or options.rectangle

    def _search(self, root: TreeNode) -> tuple[list[list[int]], int]:
        open_list: list[tuple[int, int, int, _Node]] = []
        self._push(open_list, root)
        while open_list:
            self.deadline.check()
            node = heappop(open_list)[3]
            if not node.conflicts:
                return node.paths, self.first_root_soc
            self.stats.high += 1
            conflict = min(node.conflicts)
            a, b = conflict[2], conflict[3]
            if self.merge_threshold:
                self._tally(node, a, b)
            pos = positions(node.paths)
            branches = conflict[6] or [(c,) for c in split(conflict[1:6])]
            children = []
            for child in self._children(node, a, b, branches, pos):
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

    def _low_level(
        self, agent: int, table: ConstraintTable, cat: ConflictAvoidanceTable | None
    ) -> tuple[list[int], int] | None:
        path = space_time_astar(
            self.graph,
            self.starts[agent],
            self.goals[agent],
            table,
            cat,
            self.deadline,
            self.stats,
        )
        return None if path is None else (path, path_cost(path))

    def _new_root(self, paths: list[list[int]], bounds: list[int]) -> _Node:
        return _Node(None, (), paths, [path_cost(p) for p in paths], {})

    def _set_conflicts(
        self, node: _Node, kept: list[Classified], new: list[Conflict], pos: np.ndarray
    ) -> None:
        now = positions(node.paths) if new and self._symmetric else pos
        node.conflicts = kept + [self._classify(node, c, now) for c in new]
        node.h = self._heuristic(node)

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
