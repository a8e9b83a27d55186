"""How the coordinator turns the floor plan into tasks, and a won task into a robot's plan.

Tasks: one coverage tour of the whole floor for one robot from the dock
(``planners.coverage.plan_coverage``: rooms, boustrophedon cells, ordered sweeps), cut into
consecutive pieces of about ``coordinator.task_target_s`` of cleaning
(``planners.auction.split_tour``). The tour does not depend on how many robots come, or where
they are, so a restarted coordinator or a changed fleet prices the same tasks.

Plans: the transit from where the robot reports itself to the end of the task it enters by (A*
on the floor plan inflated by the robot, ``planners.coverage.transit``), then the task's sweep
in the direction it won it, and the sweeps of the tasks queued after it that begin where it
ends (a region's run of the tour is one plan: the robot does not stop between its tasks).

The tour is planned by :func:`fleet_tour_spec`'s :meth:`TourSpec.plan`, which ``fleet plan
coverage`` and ``fleet bench coverage`` call too, so the figures a user reads are those of the
plan the fleet drives. The coordinator keeps the tour's own figures and its elements (lanes,
turns, passes, hops: ``planners.tour_elements``) for the run's report (:attr:`TaskPlanner.meta`).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fleet.params import FleetConfig
from fleet.world import World
from planners.auction import Task, TravelGrid, floor_travel, split_tour
from planners.bodies import Rerouted, reroute, with_bodies
from planners.coverage import CoverageParams, CoveragePlan, plan_coverage
from planners.coverage.metrics import swath
from planners.coverage.transit import Transit
from planners.grid import GridMap, clearance, dilate, reachable
from planners.polyline import densify, ending_at, without_straight_vertices
from planners.robot import RobotSpec
from planners.tour_elements import plan_elements

PLAN_RESOLUTION = 0.025
# the bare planner (`fleet plan coverage --bare`): the coverage section as it is, on the
# simulator's cleaning grid, for the bare robot radius
BARE_RESOLUTION = 0.05

log = logging.getLogger("coordinator")


@dataclass(frozen=True)
class TourSpec:
    """How a coverage plan is made: the grid's cell size (m), the planner's parameters, and
    what a robot centre keeps from obstacles beyond the robot's radius (m)."""

    resolution: float
    params: CoverageParams
    wall_clearance: float

    def grid(self, world: World) -> GridMap:
        """The world's floor plan at :attr:`resolution`."""
        return world.grid(self.resolution)

    def plan(
        self, grid: GridMap, starts: Sequence[tuple[float, float]], robot: RobotSpec
    ) -> CoveragePlan:
        """The coverage plan of ``grid`` (:meth:`grid`) for ``robot`` from ``starts``."""
        return plan_coverage(grid, starts, self.params, robot, wall_clearance=self.wall_clearance)

    def to_json(self) -> dict[str, float]:
        """The parameters that set the plan apart: cell size, lane overlap, wall clearance."""
        return {
            "resolution_m": self.resolution,
            "lane_overlap": self.params.overlap,
            "wall_clearance_m": self.wall_clearance,
        }


def fleet_tour_spec(cfg: FleetConfig) -> TourSpec:
    """The coordinator's plan: 2.5 cm, lanes ``coordinator.lane_overlap`` of the brush apart
    (a real robot tracks its lane only to a few centimetres), centres kept
    ``coordinator.wall_clearance`` beyond the radius (the DWA needs clearance above the radius
    plus the noise of a median-filtered scan)."""
    params = dataclasses.replace(cfg.coverage, overlap=cfg.coordinator.lane_overlap)
    return TourSpec(PLAN_RESOLUTION, params, cfg.coordinator.wall_clearance)


def bare_tour_spec(cfg: FleetConfig) -> TourSpec:
    """The planner alone: 5 cm, the ``coverage`` section as it is (``coverage.overlap``), the
    bare robot radius. Not what the fleet drives; kept to compare with earlier figures."""
    return TourSpec(BARE_RESOLUTION, cfg.coverage, 0.0)


def tour_figures(plan: CoveragePlan, tasks: Sequence[Task], spec: TourSpec) -> dict[str, Any]:
    """The one-robot tour's own figures, judged on its own floor (robot centres kept radius +
    wall clearance from obstacles, at its resolution): coverage, repetition, path length,
    turns, the planner's time estimate, and the tasks' summed drive time (what the market
    prices), with the parameters that made it."""
    m = plan.metrics
    return {
        "coverage": round(m.total.coverage, 5),
        "repetition": round(m.total.repetition, 5),
        "path_length_m": round(m.total.path_length_m, 3),
        "turns": m.total.turns,
        "estimate_s": round(m.makespan_s, 2),
        "task_time_s": round(sum(t.time_s for t in tasks), 2),
        "tasks": len(tasks),
        **spec.to_json(),
    }


class TaskPlanner:
    """Tasks of the known floor plan, and plans that drive them."""

    def __init__(self, world: World, cfg: FleetConfig) -> None:
        self._configure(cfg)
        # the file the floor plan came from: the world's, or a stored map's (`--map`)
        self.floor = str(world.source)
        grid = self.spec.grid(world)
        self.dock = tuple(float(v) for v in world.start_poses(1, cfg.robot.radius)[0][:2])
        centres = clearance(grid) >= self.centre_clearance
        self.use_floor(grid, reachable(centres, grid.world_to_cell(np.array([self.dock]))))

    def _configure(self, cfg: FleetConfig) -> None:
        """What does not depend on the floor: the tour's spec, the robot, the clearances."""
        self.spec = fleet_tour_spec(cfg)
        self.target_s = cfg.coordinator.task_target_s
        self.robot = cfg.robot
        self.wall_clearance = self.spec.wall_clearance
        # what a robot centre keeps from obstacles, and from the bodies of lost robots
        self.centre_clearance = self.robot.radius + self.wall_clearance
        self.params = self.spec.params
        # what the run's report reads from the job's store: the tour's figures and elements
        self.meta: dict[str, Any] = {}
        # a lost robot's body: its radius, and the error of the pose it last reported
        self.body_radius = cfg.robot.radius + cfg.coordinator.body_margin
        self.max_detour = cfg.coordinator.max_detour_m
        self.bodies = np.zeros((0, 2))
        # travel is priced at the speed the robots' bids assume
        self.transit_speed = cfg.agent.transit_speed
        # the tour is being planned (the coordinator's lock not held): the floor stays as it is
        self.planning = False

    def use_floor(self, grid: GridMap, centres: np.ndarray) -> None:
        """Plan on ``grid`` from now on, robot centres on the cells ``centres`` (those a robot
        reaches), around the bodies of lost robots known so far."""
        self.grid = grid
        self.reachable = centres
        self.transit = Transit(grid, centres)
        # floor the brush reaches from some robot centre, without bodies and with them
        self.brushable = self._brushable(centres)
        self.brushable_now = self.brushable
        self._counted = np.zeros(grid.shape, dtype=bool)
        if len(self.bodies):
            self.set_bodies(self.bodies)

    def tasks(self) -> tuple[Task, ...]:
        """The tour from the dock cut into tasks; fills :attr:`meta` (``tour``: its figures,
        ``tour_elements``: its elements, None when they cannot be told apart; the tour's
        ``floor`` names the file it was planned on)."""
        result = self.spec.plan(self.grid, [self.dock], self.robot)
        m = result.metrics
        tasks = split_tour(
            result.paths[0], result.cell_labels, self.grid, self.target_s, self.params, self.robot
        )
        try:
            elements: dict[str, Any] | None = plan_elements(result).to_json()
        except ValueError as e:
            log.warning("the tour's elements cannot be told apart: %s", e)
            elements = None
        tour = tour_figures(result, tasks, self.spec) | {"floor": self.floor}
        self.meta = {"tour": tour, "tour_elements": elements}
        # judged on the plan's own floor: centres kept radius + wall clearance from obstacles
        log.info(
            "tour: coverage %.1f %%, repetition %.1f %%, %.1f m, %.0f s for one robot, "
            "cut into %d tasks of about %.0f s",
            100 * m.total.coverage,
            100 * m.total.repetition,
            m.total.path_length_m,
            m.makespan_s,
            len(tasks),
            self.target_s,
        )
        return tasks

    def travel(self) -> TravelGrid:
        """Travel times on the floor plan as the robots' bids price them: obstacles grown by the
        radius, at ``agent.transit_speed`` (``planners.auction.floor_travel``, as
        ``agents.market.MarketClient.use_floor``)."""
        return floor_travel(self.grid, self.robot.radius, self.transit_speed)

    def drive(
        self,
        from_xy: tuple[float, float],
        chain: list[tuple[Task, bool]],
        transit: np.ndarray | None = None,
    ) -> tuple[np.ndarray, list[int]]:
        """(waypoints, where each task's sweep begins): the transit to the first task, then the
        sweeps of ``chain`` ((task, reverse) pairs, each beginning where the one before ends).
        The transit is ``transit`` (points of a transit planned in space and time, kept as they
        are: the order of passage numbers them; run on to the first sweep's start unless it
        ends there), else A* on the floor plan around the bodies of lost robots; ValueError
        when there is no way from ``from_xy`` to the first task."""
        sweeps = [task.path[::-1] if reverse else task.path for task, reverse in chain]
        start = np.asarray(from_xy, dtype=float)
        if transit is not None:
            leg = ending_at(transit, sweeps[0][0])
        else:
            leg = self.transit.path(start, sweeps[0][0])
            leg = without_straight_vertices(np.asarray(leg, dtype=float))
        parts = [leg[:-1]]
        starts = []
        at = len(leg) - 1
        for sweep in sweeps:
            starts.append(at)
            parts.append(sweep if len(parts) == 1 else sweep[1:])
            at += len(sweep) - 1
        return np.vstack(parts), starts

    # ---- bodies of lost robots --------------------------------------------------------------

    def set_bodies(self, bodies: np.ndarray) -> None:
        """Plan around the bodies of lost robots, centred at ``bodies`` ((K, 2) world metres,
        from their last reported poses): transits from now on, and :meth:`reroute`."""
        self.bodies = np.asarray(bodies, dtype=float).reshape(-1, 2)
        grid = with_bodies(self.grid, self.bodies, self.body_radius)
        free = (clearance(grid) >= self.centre_clearance) & self.reachable
        self.transit = Transit(self.grid, free)
        self.brushable_now = self._brushable(free)
        self._counted = np.zeros(self.grid.shape, dtype=bool)

    def _brushable(self, centres: np.ndarray) -> np.ndarray:
        return dilate(centres, self.robot.cleaning_width / 2, self.grid.resolution) & (
            self.grid.free
        )

    def blocked_m2(self, path: np.ndarray) -> float:
        """The floor the brush would sweep along ``path`` that the bodies put out of every
        robot's reach (under them, or in gaps too narrow to pass), counting no floor that an
        earlier call since :meth:`set_bodies` counted (lanes overlap)."""
        swept, _ = swath(self.grid, np.asarray(path, dtype=float), self.robot.cleaning_width / 2)
        lost = swept & self.brushable & ~self.brushable_now & ~self._counted
        self._counted |= lost
        return float(lost.sum()) * self.grid.resolution**2

    def near_bodies(self, path: np.ndarray) -> bool:
        """Whether a robot centre driving ``path`` comes near enough a body to touch it."""
        return self.near(path, self.bodies, self.body_radius)

    def near(self, path: np.ndarray, centres: np.ndarray, radius: float) -> bool:
        """Whether a robot centre driving ``path`` comes within its clearance (and a cell) of
        one of the discs of ``radius`` at ``centres`` ((K, 2) world metres)."""
        centres = np.asarray(centres, dtype=float).reshape(-1, 2)
        if not len(centres):
            return False
        reach = radius + self.centre_clearance + self.grid.resolution
        pts = densify(np.asarray(path, dtype=float), self.grid.resolution)
        gaps = np.hypot(*(pts[:, None, :] - centres[None, :, :]).transpose(2, 0, 1))
        return bool(gaps.min() < reach)

    def change_floor(self, grid: GridMap) -> None:
        """Plan on ``grid`` from now on: the floor plan with furniture moved since it was made
        (:mod:`fleet.coordinator.map_changes`), robot centres on the cells clear of it that a
        robot reaches from the dock. The floor the brush reaches is the new one's, so a stretch
        of a task that runs through new furniture puts no floor out of reach."""
        centres = clearance(grid) >= self.centre_clearance
        self.use_floor(grid, reachable(centres, grid.world_to_cell(np.array([self.dock]))))

    def reroute(self, path: np.ndarray) -> Rerouted:
        """``path`` repaired round the bodies (:func:`planners.bodies.reroute`): the runs a
        robot can drive, joined round a body where a transit gets round it, and the stretches
        under or behind it."""
        return reroute(path, self.transit.free, self.grid, self.grid.resolution, self.max_detour)
