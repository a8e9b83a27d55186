"""Space-time deconfliction of one round of transits on a transit graph.

Input: robots, each with a start and a goal point (world metres) and the time it starts (s).
Output: per robot timed waypoints (x, y, t) through the cells of a ``TransitGraph`` such that no
two robots are in one cell at one time and no two swap cells along an edge (the MAPF model of
Stern et al., SoCS 2019, which ``planners.mapf`` solves and validates).

- **Time.** One MAPF step is the time to drive one cell at ``speed``
  (``step_s = cell_size / speed``); step 0 is the earliest start of the round. A robot that
  starts later waits in its start cell until its step ``round((start_time - t0) / step_s)``;
  its start cell is reserved for it meanwhile.
- **Cells.** Starts and goals are located on the graph (``TransitGraph.candidates``); robots
  whose points fall in one cell get the next nearest free cells of their region, so starts and
  goals are distinct (a robot whose goal lies in its own start cell keeps that cell). Waypoints
  are the cells' points: a robot drives from its start point to its first cell's point, and from
  its last cell's point to its goal point, on its own. A robot whose goal is not in its start's
  component is reported by name and nothing is planned.
- **Priorities** (prioritized planning, Erdmann and Lozano-Pérez 1987; Silver 2005): first the
  robots without a transit (start cell = goal cell; they reserve their cell for good), then the
  robots that start in a narrow passage (a cell with at most two neighbours), then the longer
  transits (graph distance), then by name. Each robot is planned with SIPP (Phillips and
  Likhachev, ICRA 2011; ``planners.mapf.sipp``) against the reservations of all higher
  priorities and the start cells of robots that have not left yet. A reserved cell stays
  reserved one step after its robot left it: no robot follows another nose to tail, so robots
  never rotate round a block of cells in one step, and the order of passage below has no cycle.
  A cell whose point stands too near another's (a bridge of the graph and its neighbours,
  ``TransitGraph.crowding``) is reserved with it.
- **Joint fallback.** When no order works, all robots of the round are planned jointly under
  ``joint_time_limit_s``: by CBS (``planners.mapf``'s ICBS, optimal) for rounds of at most
  ``cbs_max_robots`` robots, by ECBS with suboptimality bound ``ECBS_W`` (Barer et al. 2014)
  for larger ones, where CBS rarely finishes in time (50 robots on a warehouse grid: CBS timed
  out after 1 s where ECBS took 0.09 s). Every robot then starts at the latest start step of the
  round (until then each waits in its distinct start cell, so the joint plan stays
  conflict-free). If the joint search finds no plan either, the result says so
  (``status == "failed"``), naming the robot that prioritized planning could not place.
  ``joint_only`` skips the priorities and plans every round jointly. The joint plans may let
  robots follow each other and rotate; a joint plan whose order of passage has a cycle is
  refused (``failed``).
- **Order of passage.** ``edges`` gives each robot the action dependencies of the plan
  (Hönig et al., RA-L 2019; ``planners.dependencies``): robots that wait for them at the cells'
  points never share a cell, however late each one is.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from planners.dependencies import Dependency, dependencies, has_cycle, route_of
from planners.mapf import MapfInstance, solve
from planners.mapf.deadline import Deadline
from planners.mapf.grid_graph import UNREACHABLE, GridGraph
from planners.mapf.low_level import SearchStats
from planners.mapf.model import SearchTimeout
from planners.mapf.sipp import sipp
from planners.mapf.tables import ConstraintTable
from planners.transit_graph import Cell, TransitGraph

STATUSES = ("success", "unreachable", "failed")
# suboptimality bound of the joint fallback's ECBS (sum of costs ≤ ECBS_W · optimum)
ECBS_W = 1.5
# a cell with at most this many neighbours is part of a narrow passage (a corridor's chain)
NARROW_DEGREE = 2
# why a joint plan whose order of passage has a cycle is refused
_CYCLIC = (
    ", but it moves robots round a block of cells in one step, "
    "an order of passage no delay-tolerant execution can keep"
)


@dataclass(frozen=True)
class TransitRequest:
    """One robot's transit: from ``start`` to ``goal`` (world x, y in m), leaving at
    ``start_time`` (s)."""

    name: str
    start: tuple[float, float]
    goal: tuple[float, float]
    start_time: float = 0.0


@dataclass(frozen=True)
class Transit:
    """One robot's plan: ``cells[s]`` is its cell at step s (it stays in the last one), and
    ``waypoints`` the (x, y, t) of each arrival and, where it waits, each departure."""

    name: str
    cells: tuple[Cell, ...]
    waypoints: tuple[tuple[float, float, float], ...]


@dataclass(frozen=True)
class RoundPlan:
    """The plan of a round. ``transits`` is empty unless ``status == "success"``.

    ``method`` is ``"pp"`` (prioritized planning), ``"cbs"`` or ``"ecbs"`` (the joint fallback);
    ``unreachable`` names the robots whose goal no way leads to; ``instance`` is the MAPF
    instance on the graph's cells (for ``planners.mapf.validate``); ``edges`` the order of
    passage of each robot through the cells it shares with others (``planners.dependencies``).
    """

    status: str
    method: str
    transits: tuple[Transit, ...]
    t0: float
    step_s: float
    order: tuple[str, ...] = ()
    unreachable: tuple[str, ...] = ()
    message: str = ""
    instance: MapfInstance | None = field(default=None, compare=False)
    start_steps: tuple[int, ...] = ()
    runtime_s: float = 0.0
    edges: Mapping[str, tuple[Dependency, ...]] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"status must be one of {STATUSES}, got {self.status!r}")


def _assign(
    candidates: list[list[Cell]], keep: Sequence[Cell | None] | None = None
) -> list[Cell | None]:
    """The nearest cell of each robot not taken by another (None if all are): robots whose
    nearest cell is ``keep[i]`` (their start cell, for goals) choose first, then the others in
    list order."""
    order = list(range(len(candidates)))
    if keep is not None:
        order.sort(key=lambda i: not (candidates[i] and candidates[i][0] == keep[i]))
    taken: set[Cell] = set()
    out: list[Cell | None] = [None] * len(candidates)
    for i in order:
        cell = next((c for c in candidates[i] if c not in taken), None)
        if cell is not None:
            taken.add(cell)
        out[i] = cell
    return out


def _waypoints(
    graph: TransitGraph, cells: Sequence[Cell], t0: float, step_s: float
) -> tuple[tuple[float, float, float], ...]:
    out = []
    last = len(cells) - 1
    for s, cell in enumerate(cells):
        arrives = s == 0 or cells[s - 1] != cell
        leaves = s < last and cells[s + 1] != cell
        if arrives or leaves:
            x, y = graph.point(cell)
            out.append((x, y, t0 + s * step_s))
    return tuple(out)


def _trim(path: list[Cell]) -> list[Cell]:
    end = len(path)
    while end > 1 and path[end - 2] == path[-1]:
        end -= 1
    return path[:end]


def plan_round(
    graph: TransitGraph,
    requests: Sequence[TransitRequest],
    speed: float,
    joint_time_limit_s: float = 1.0,
    max_reorders: int = 8,
    cbs_max_robots: int = 10,
    joint_only: bool = False,
) -> RoundPlan:
    """Conflict-free timed transits for ``requests`` on ``graph`` at ``speed`` (m/s);
    ``max_reorders`` bounds the priority orders tried after the first (see the module);
    ``joint_only`` plans the round jointly without trying priorities first."""
    deadline = Deadline(float("inf"))
    names = _names(requests, speed)
    step_s = graph.cell_size / speed
    t0 = min((r.start_time for r in requests), default=0.0)
    if not requests:
        return RoundPlan("success", "pp", (), t0, step_s)
    located = _cells(graph, requests, t0, step_s, deadline)
    if isinstance(located, RoundPlan):
        return located
    starts, goals = located
    mg = graph.graph
    start_ids, goal_ids = [mg.cell(s) for s in starts], [mg.cell(g) for g in goals]
    holds = [max(0, round((r.start_time - t0) / step_s)) for r in requests]
    instance = MapfInstance(graph.usable, tuple(starts), tuple(goals), tuple(names))
    mg.precompute(goal_ids)
    order = _first_order(graph, starts, start_ids, goal_ids, names)
    paths: list[list[Cell]] | int = 0
    if not joint_only:
        paths, order = _by_priorities(
            graph, start_ids, goal_ids, holds, order, max_reorders, deadline
        )
    method, message = "pp", ""
    if isinstance(paths, int):
        why = "" if joint_only else f"prioritized planning found no path for {names[paths]}; "
        method = "cbs" if len(requests) <= cbs_max_robots else "ecbs"
        joint = _jointly(instance, method, joint_time_limit_s, holds, mg)
        if isinstance(joint, str):
            return RoundPlan(
                "failed",
                method,
                (),
                t0,
                step_s,
                order=tuple(names[i] for i in order),
                message=f"{why}{method.upper()}: {joint}",
                instance=instance,
                runtime_s=deadline.elapsed(),
            )
        paths, holds = joint
        message = f"{why}{method.upper()} planned the round"
    transits, edges, cyclic = _passage(graph, names, paths, t0, step_s, method != "pp")
    if cyclic:
        return RoundPlan(
            "failed",
            method,
            (),
            t0,
            step_s,
            message=message + _CYCLIC,
            instance=instance,
            runtime_s=deadline.elapsed(),
        )
    return RoundPlan(
        "success",
        method,
        transits,
        t0,
        step_s,
        order=tuple(names[i] for i in order),
        message=message,
        instance=instance,
        start_steps=tuple(holds),
        runtime_s=deadline.elapsed(),
        edges=edges,
    )


def _names(requests: Sequence[TransitRequest], speed: float) -> list[str]:
    """The robots' names; raises ValueError for a speed ≤ 0 or a name given twice."""
    if speed <= 0:
        raise ValueError(f"speed must be > 0, got {speed}")
    names = [r.name for r in requests]
    if len(set(names)) != len(names):
        raise ValueError(f"robot names must be distinct, got {names}")
    return names


def _jointly(
    instance: MapfInstance,
    method: str,
    time_limit_s: float,
    holds: Sequence[int],
    graph: GridGraph,
) -> tuple[list[list[Cell]], list[int]] | str:
    """The joint fallback by ``method`` on ``graph`` (the transit graph's): the paths (every
    robot waits in its start cell until the latest start step) and the robots' start steps, or
    why there are none."""
    result = solve(instance, method, w=ECBS_W, time_limit_s=time_limit_s, graph=graph)
    if result.solution is None:
        return f"{result.status} ({result.message})"
    wait = max(holds)
    paths = [[p[0]] * wait + list(p) for p in result.solution.paths]
    return paths, [wait] * len(holds)


def _passage(
    graph: TransitGraph,
    names: Sequence[str],
    paths: Sequence[Sequence[Cell]],
    t0: float,
    step_s: float,
    joint: bool,
) -> tuple[tuple[Transit, ...], dict[str, tuple[Dependency, ...]], bool]:
    """The robots' transits, their order of passage (``planners.dependencies``) and, for a
    ``joint`` plan, whether that order has a cycle (prioritized plans have none, see the
    module)."""
    transits = tuple(
        Transit(name, tuple(path), _waypoints(graph, path, t0, step_s))
        for name, path in zip(names, paths, strict=True)
    )
    routes = [route_of(t.name, t.cells) for t in transits]
    edges = dependencies(routes)
    return transits, edges, joint and has_cycle(routes, edges)


def _cells(
    graph: TransitGraph,
    requests: Sequence[TransitRequest],
    t0: float,
    step_s: float,
    deadline: Deadline,
) -> tuple[list[Cell], list[Cell]] | RoundPlan:
    """Distinct start and goal cells of the robots (``_assign``), or the ``unreachable`` plan
    naming the robots without a free cell for their start or goal or with a goal in another
    component."""
    starts = _assign(graph.candidates(np.array([r.start for r in requests])))
    goals = _assign(graph.candidates(np.array([r.goal for r in requests])), starts)
    problems = []
    for r, s, g in zip(requests, starts, goals, strict=True):
        if s is None:
            problems.append(f"{r.name}: no free cell for its start {r.start}")
        elif g is None:
            problems.append(f"{r.name}: no free cell for its goal {r.goal}")
        elif graph.component[s] != graph.component[g]:
            problems.append(f"{r.name}: its goal {r.goal} cannot be reached from {r.start}")
    if not problems:
        return starts, goals  # type: ignore[return-value]
    return RoundPlan(
        "unreachable",
        "none",
        (),
        t0,
        step_s,
        unreachable=tuple(p.split(":", 1)[0] for p in problems),
        message="; ".join(problems),
        runtime_s=deadline.elapsed(),
    )


def _first_order(
    graph: TransitGraph,
    starts: Sequence[Cell],
    start_ids: Sequence[int],
    goal_ids: Sequence[int],
    names: Sequence[str],
) -> list[int]:
    """The rule order: robots without a transit, then those starting in a narrow passage, then
    the longer transits, then by name."""
    deg = graph.degree()
    dist = [graph.graph.distances(g)[s] for s, g in zip(start_ids, goal_ids, strict=True)]
    return sorted(
        range(len(starts)),
        key=lambda i: (
            start_ids[i] != goal_ids[i],
            deg[starts[i]] > NARROW_DEGREE,
            -dist[i],
            names[i],
        ),
    )


def _by_priorities(
    graph: TransitGraph,
    start_ids: Sequence[int],
    goal_ids: Sequence[int],
    holds: Sequence[int],
    order: list[int],
    max_reorders: int,
    deadline: Deadline,
) -> tuple[list[list[Cell]] | int, list[int]]:
    """Prioritized planning in ``order``, the robot that found no path raised first (it keeps its
    place among the idle ones), up to ``max_reorders`` more orders: the paths, or the last robot
    that found none; and the last order tried."""
    paths = _prioritized(graph, start_ids, goal_ids, holds, order, deadline)
    tried = {tuple(order)}
    while isinstance(paths, int) and len(tried) <= max_reorders:
        stuck_robot = paths
        rest = [i for i in order if i != stuck_robot]
        idle = sum(start_ids[i] == goal_ids[i] for i in rest)
        order = [*rest[:idle], stuck_robot, *rest[idle:]]
        if tuple(order) in tried:
            break
        tried.add(tuple(order))
        paths = _prioritized(graph, start_ids, goal_ids, holds, order, deadline)
    return paths, order


def _prioritized(
    graph: TransitGraph,
    starts: Sequence[int],
    goals: Sequence[int],
    holds: Sequence[int],
    order: Sequence[int],
    deadline: Deadline,
) -> list[list[Cell]] | int:
    """SIPP for each robot in ``order`` against the higher priorities' reservations; the paths
    (cells per step), or the index of the first robot that found none."""
    mg = graph.graph
    n = mg.num_cells
    crowd = graph.crowding()
    planned: list[list[int]] = []
    paths: list[list[Cell] | None] = [None] * len(starts)
    stats = SearchStats()
    for i in order:
        if mg.distances(goals[i])[starts[i]] >= UNREACHABLE:
            return i
        table = ConstraintTable(n)
        for path in planned:
            table.reserve_path(path)
            # and one step after each stay: no robot follows another nose to tail
            for t in range(len(path) - 1):
                table.add_vertex(path[t], t + 1)
            if not crowd.keys().isdisjoint(path):
                # nor stands in a cell whose point is too near (a bridge's neighbours)
                for t in range(len(path) - 1):
                    for other in crowd.get(path[t], ()):
                        table.add_vertex(other, t)
                        table.add_vertex(other, t + 1)
                for other in crowd.get(path[-1], ()):
                    table.add_parked(other, len(path) - 1)
        for j, start in enumerate(starts):
            if j != i and paths[j] is None:
                for t in range(holds[j] + 2):
                    for cell in (start, *crowd.get(start, ())):
                        table.add_vertex(cell, t)
        # a robot that starts later may not leave its start cell before its start step
        for t in range(1, holds[i] + 1):
            for nb in mg.neighbours[starts[i]]:
                table.add_vertex(nb, t)
        try:
            path = sipp(mg, starts[i], goals[i], table, deadline, stats)
        except SearchTimeout:
            path = None
        if path is None:
            return i
        planned.append(path)
        paths[i] = _trim([mg.rc(c) for c in path])
    return paths  # type: ignore[return-value]
