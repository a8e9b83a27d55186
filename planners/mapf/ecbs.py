"""Enhanced CBS, ECBS(w) (Barer, Sharon, Stern and Felner, SoCS 2014): bounded-suboptimal MAPF.

Both levels are focal searches. The low level (``focal_astar``) returns a path of cost at most
``w`` times the optimum under the agent's constraints, preferring few collisions with the other
agents, and a lower bound ``f_min``. A high-level node's lower bound ``LB`` is the sum of its
agents' bounds; the high level expands, among the nodes with ``SOC ≤ w · min LB``, the one with the
fewest conflicts. The returned SOC is therefore at most ``w`` times the optimal SOC.
"""

from __future__ import annotations

from collections.abc import Sequence
from heapq import heappop, heappush

from planners.mapf.conflicts import all_conflicts, conflicts_of, positions
from planners.mapf.deadline import Deadline
from planners.mapf.grid_graph import GridGraph
from planners.mapf.low_level import SearchStats, focal_astar
from planners.mapf.model import InfeasibleInstanceError, path_cost
from planners.mapf.tables import ConflictAvoidanceTable, ConstraintTable

Constraint = tuple[int, int, int]


class _Node:
    __slots__ = (
        "agent",
        "conflicts",
        "constraint",
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
        agent: int,
        constraint: Constraint | None,
        paths: list[list[int]],
        costs: list[int],
        lbs: list[int],
    ) -> None:
        self.parent = parent
        self.agent = agent
        self.constraint = constraint
        self.paths = paths
        self.costs = costs
        self.lbs = lbs
        self.soc = sum(costs)
        self.lb = sum(lbs)
        self.conflicts: list[tuple[int, int, int, int, int]] = []
        self.done = False


def ecbs(
    graph: GridGraph,
    starts: Sequence[int],
    goals: Sequence[int],
    w: float,
    deadline: Deadline,
    stats: SearchStats,
) -> tuple[list[list[int]], int]:
    """Paths with SOC ≤ w · optimum, and the lower bound that proves it; raises SearchTimeout."""
    if w < 1.0:
        raise ValueError(f"w must be ≥ 1, got {w}")
    n = graph.num_cells
    k = len(starts)
    graph.precompute(goals)

    def table_for(node: _Node, agent: int) -> ConstraintTable:
        table = ConstraintTable(n)
        while node.parent is not None:
            if node.agent == agent:
                u, v, t = node.constraint
                if v == -1:
                    table.add_vertex(u, t)
                else:
                    table.add_edge(u, v, t)
            node = node.parent
        return table

    paths: list[list[int]] = []
    lbs: list[int] = []
    for i in range(k):
        found = focal_astar(
            graph,
            starts[i],
            goals[i],
            ConstraintTable(n),
            ConflictAvoidanceTable.from_paths(n, paths),
            w,
            deadline,
            stats,
        )
        if found is None:
            raise RuntimeError("an agent has no path although its goal is reachable")
        paths.append(found[0])
        lbs.append(found[1])
    root = _Node(None, -1, None, paths, [path_cost(p) for p in paths], lbs)
    root.conflicts = all_conflicts(paths)

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
        deadline.check()
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
        stats.high += 1
        t, a, b, u, v = min(node.conflicts)
        split = [(a, (u, -1, t)), (b, (u, -1, t))] if v == -1 else [(a, (u, v, t)), (b, (v, u, t))]
        pos = positions(node.paths)
        lengths = [len(p) for p in node.paths]
        for agent, constraint in split:
            child = _Node(
                node, agent, constraint, list(node.paths), list(node.costs), list(node.lbs)
            )
            found = focal_astar(
                graph,
                starts[agent],
                goals[agent],
                table_for(child, agent),
                ConflictAvoidanceTable.from_positions(n, pos, lengths, agent),
                w,
                deadline,
                stats,
            )
            if found is None:
                continue
            path, f_min = found
            child.paths[agent] = path
            child.costs[agent] = path_cost(path)
            child.lbs[agent] = max(child.lbs[agent], f_min)
            child.soc = sum(child.costs)
            child.lb = sum(child.lbs)
            kept = [c for c in node.conflicts if c[1] != agent and c[2] != agent]
            child.conflicts = kept + conflicts_of(agent, path, pos)
            push(child)
