"""Multi-agent path finding on 4-connected grids: PP, SIPP-PP, CBS (ICBS) and ECBS.

Entry point for the rest of the system::

    from planners.mapf import MapfInstance, solve

    instance = MapfInstance(free=free_bool_array, starts=((r0, c0), ...), goals=((r1, c1), ...))
    result = solve(instance, "ecbs", w=1.2, time_limit_s=2.0)
    if result.status == "success":
        paths = result.solution.paths        # paths[i][t] = (row, col); agents stay at the end
    # result.status: "success" | "timeout" | "infeasible" (rejected before search, or CBS/ECBS
    # proved there is none; reason in result.message) | "failed" (PP: every priority order
    # failed, or max_restarts exhausted)

Solvers (``SOLVERS``):

- ``"pp"``: prioritized planning with space-time A*, randomized restarts (fast, incomplete); it
  gives up once every order of a small group has failed.
- ``"sipp-pp"``: the same with SIPP as single-agent planner.
- ``"cbs"``: ICBS, optimal sum of costs (cardinal conflicts via MDDs, bypass, CG heuristic), with
  target reasoning (length constraints for agents parked on their goals), corridor and rectangle
  reasoning (range and barrier constraints, ``symmetry``) and meta-agents (agents that keep
  conflicting are merged and planned by an optimal joint A* with operator decomposition,
  ``joint``), so agents that block each other in dead ends are solved quickly.
- ``"cbs-plain"``: CBS without those improvements, the textbook baseline of ``fleet bench mapf``;
  it can split target conflicts one timestep at a time for a very long while on tiny instances.
- ``"ecbs"``: ECBS(w), SOC ≤ w · optimum, with the same target, corridor and rectangle reasoning
  and meta-agents.

Model, formats and checks: ``model`` (costs, feasibility check), ``movingai`` (.map/.scen),
``yaml_format`` (libMultiRobotPlanning YAML), ``validate`` (independent solution checker),
``generate`` (seeded benchmark maps and scenarios), ``brute_force`` (the optimum of tiny
instances by exhaustive joint search), ``tiny`` (every solver against it: ``fleet bench mapf
--tiny``). All solvers are deterministic for a given input (and seed), and honour
``time_limit_s`` by returning status ``"timeout"``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from planners.mapf.cbs import PLAIN_CBS, CbsOptions, ConflictBasedSearch
from planners.mapf.deadline import Deadline
from planners.mapf.ecbs import ecbs
from planners.mapf.grid_graph import GridGraph
from planners.mapf.low_level import SearchStats
from planners.mapf.model import (
    InfeasibleInstanceError,
    MapfInstance,
    MapfResult,
    MapfSolution,
    SearchTimeout,
    check_instance,
)
from planners.mapf.prioritized import prioritized
from planners.mapf.validate import ValidationReport, validate

SOLVERS = ("pp", "sipp-pp", "cbs", "cbs-plain", "ecbs")

__all__ = [
    "SOLVERS",
    "CbsOptions",
    "InfeasibleInstanceError",
    "MapfInstance",
    "MapfResult",
    "MapfSolution",
    "ValidationReport",
    "check_instance",
    "solve",
    "validate",
]


def solve(
    instance: MapfInstance,
    solver: str,
    w: float = 1.2,
    time_limit_s: float = 10.0,
    *,
    order: Sequence[int] | None = None,
    seed: int = 0,
    max_restarts: int | None = None,
    cbs_options: CbsOptions | None = None,
    graph: GridGraph | None = None,
) -> MapfResult:
    """Solve ``instance`` with ``solver`` (one of ``SOLVERS``) within ``time_limit_s`` seconds.

    ``w`` is the ECBS suboptimality bound; ``order``, ``seed`` and ``max_restarts`` configure
    prioritized planning (priority order, restart shuffles, None = restart until the deadline);
    ``graph`` lets repeated calls on one map share its cached distance tables.
    """
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
    deadline = Deadline(time_limit_s)
    try:
        check_instance(instance)
    except InfeasibleInstanceError as err:
        return MapfResult("infeasible", solver, None, deadline.elapsed(), message=str(err))
    same_map = graph is not None and np.array_equal(graph.free, instance.free)
    if graph is None or not same_map:
        graph = GridGraph(instance.free)
    starts = [graph.cell(s) for s in instance.starts]
    goals = [graph.cell(g) for g in instance.goals]
    stats = SearchStats()
    lower_bound: int | None = None
    details: dict[str, object] = {}
    try:
        if solver in ("pp", "sipp-pp"):
            low_level = "sipp" if solver == "sipp-pp" else "astar"
            paths, used, attempts = prioritized(
                graph, starts, goals, order, low_level, seed, max_restarts, deadline, stats
            )
            details = {"order": list(used), "attempts": attempts}
            if paths is None:
                message = f"no priority order worked ({attempts} tried; PP is incomplete)"
                return _unsolved("failed", solver, deadline, stats, message, details)
        elif solver == "ecbs":
            paths, lower_bound = ecbs(graph, starts, goals, w, deadline, stats)
            details = {"w": w}
        else:
            options = PLAIN_CBS if solver == "cbs-plain" else (cbs_options or CbsOptions())
            search = ConflictBasedSearch(graph, starts, goals, options, deadline, stats)
            paths, _ = search.run()
    except InfeasibleInstanceError as err:
        return _unsolved("infeasible", solver, deadline, stats, str(err), {})
    except SearchTimeout:
        message = f"no solution within {time_limit_s:g} s"
        return _unsolved("timeout", solver, deadline, stats, message, details)
    solution = MapfSolution(tuple(tuple(graph.rc(c) for c in _trim(p)) for p in paths))
    if solver.startswith("cbs"):
        lower_bound = solution.soc
    return MapfResult(
        "success",
        solver,
        solution,
        deadline.elapsed(),
        stats.high,
        stats.low,
        lower_bound,
        details=details,
    )


def _unsolved(
    status: str,
    solver: str,
    deadline: Deadline,
    stats: SearchStats,
    message: str,
    details: dict[str, object],
) -> MapfResult:
    """The result of a search that found no solution (``status``: why)."""
    return MapfResult(
        status,
        solver,
        None,
        deadline.elapsed(),
        stats.high,
        stats.low,
        message=message,
        details=details,
    )


def _trim(path: list[int]) -> list[int]:
    end = len(path)
    while end > 1 and path[end - 2] == path[-1]:
        end -= 1
    return path[:end]
