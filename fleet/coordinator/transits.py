"""Transits between tasks planned in space and time (``coordinator.deconfliction``).

``local`` (the default): a robot's transit is A* on the floor plan and robots give way to each
other only at close range, by their intents. ``prioritized`` and ``cbs``: whenever the
coordinator sends new plans, it plans the transits of a round together on the transit graph of
the floor plan (``planners.transit_graph``, ``planners.deconfliction``): the robots getting a
new plan, and the robots still in transit (planned again from where they are), against the
cells of the robots that stand still (without work, or lost: a dead robot's body stays where it
stopped). ``prioritized`` plans them by priorities with SIPP and falls back to CBS; ``cbs``
plans every round jointly. Each transit goes out as the points of its cells that the order of
passage pins or line of sight needs (``planners.dependencies.thin``: a 4-connected staircase of
cells would be a turn in place at every cell), with its order of passage renumbered to them,
which the agents keep (``agents.passage``); on such a transit a robot gives way by rank only to
the peers the plan does not order it against. Robots that sweep are not in the round: their
sweeps are not planned in time, and the DWA and the intents keep them apart from the transits
at close range.

A round that cannot be planned (a goal no way leads to, or no joint plan in time) is reported,
and its robots get ``local`` transits.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from fleet.coordinator.planning import PLAN_RESOLUTION
from fleet.params import DECONFLICTION_MODES, FleetConfig
from fleet.world import World
from planners.deconfliction import RoundPlan, TransitRequest, plan_round
from planners.dependencies import renumber, route_of, thin
from planners.transit_graph import TransitGraph, build_transit_graph

log = logging.getLogger("coordinator")

# The fine grid the transit graph is built on: the coverage plan's own, so that every place
# the plan sends a robot centre is a possible centre of the graph too. On the simulator's 5 cm
# grid, which rasterizes walls conservatively, a corridor 0.45 m between its faces keeps 0.40 m
# free, less than a robot centre needs, and its rooms fell apart into two components.
GRAPH_RESOLUTION = PLAN_RESOLUTION


@dataclass(frozen=True, eq=False)
class PlannedTransit:
    """One robot's transit of a round: its waypoints (the cells' points; the first is where the
    robot stands when it is in its start cell already, the last its goal when that is in its
    last cell), and its dependencies as rows of (waypoint, peer, the peer's waypoint it waits
    for)."""

    waypoints: np.ndarray
    waits: tuple[tuple[int, str, int], ...]
    arrivals_s: np.ndarray  # planned sim time of reaching each waypoint


class TransitPlanner:
    """The transit graph of the floor plan and the rounds planned on it."""

    def __init__(
        self,
        world: World,
        cfg: FleetConfig,
        mode: str,
        clear: Callable[[np.ndarray, np.ndarray], bool],
    ) -> None:
        """``clear(a, b)``: whether a robot centre may move straight from a to b on the floor
        plan (the coordinator's A* transits use the same test)."""
        if mode not in DECONFLICTION_MODES:
            raise ValueError(
                f"deconfliction must be one of {', '.join(DECONFLICTION_MODES)}, got {mode!r}"
            )
        self.mode = mode
        self.clear = clear
        self.speed = cfg.agent.transit_speed
        self.graph: TransitGraph = build_transit_graph(
            world.grid(GRAPH_RESOLUTION), cfg.robot.radius, cfg.coordinator.wall_clearance
        )

    def plan(
        self,
        now: float,
        moving: Mapping[str, tuple[tuple[float, float], tuple[float, float]]],
        parked: Mapping[str, tuple[float, float]],
    ) -> tuple[RoundPlan, dict[str, PlannedTransit]]:
        """Plan the transits of ``moving`` ((from, to) per robot) around ``parked`` robots."""
        requests = [TransitRequest(rid, a, b, now) for rid, (a, b) in sorted(moving.items())]
        requests += [TransitRequest(rid, xy, xy, now) for rid, xy in sorted(parked.items())]
        plan = plan_round(self.graph, requests, self.speed, joint_only=self.mode == "cbs")
        if plan.status != "success":
            return plan, {}
        routes = {t.name: route_of(t.name, t.cells) for t in plan.transits}
        pinned: dict[str, set[int]] = {name: set() for name in routes}
        for name, deps in plan.edges.items():
            for d in deps:
                pinned[name].add(d.index - 1)
                pinned[d.peer].add(d.passed)
        points = {
            name: np.array([self.graph.point(c) for c in r.cells], dtype=float)
            for name, r in routes.items()
        }
        for name, (start, goal) in moving.items():
            # a robot's own start and goal cells run from its start and into its goal: a
            # cell's point lies up to half a cell beside or beyond them, a turn in place at
            # each end. A goal in a cell given to another robot (two goals in one cell) keeps
            # its route's last cell, and the robot drives on from there on its own.
            first, last = self.graph.locate(np.array([start, goal]))
            if first == routes[name].cells[0]:
                points[name][0] = start
            if last == routes[name].cells[-1] and len(routes[name].cells) > 1:
                points[name][-1] = goal
        kept = {name: thin(points[name], pinned[name], self.clear) for name in routes}
        edges = renumber(plan.edges, kept)
        out = {}
        for name in moving:
            k = kept[name]
            arrivals = plan.t0 + np.array(routes[name].arrivals, dtype=float)[k] * plan.step_s
            waits = tuple((d.index, d.peer, d.passed) for d in edges[name])
            out[name] = PlannedTransit(points[name][k], waits, arrivals)
        return plan, out
