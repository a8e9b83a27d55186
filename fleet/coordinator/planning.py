"""How the coordinator turns the floor plan and the robots' start positions into paths.

One coverage plan (``planners.coverage.plan_coverage``: rooms, boustrophedon cells, ordered
sweeps, a makespan-balanced split) gives each robot its path. Auctions and space-time
deconfliction replace the split behind the same ``plan`` call.

The plan is sensitive to where the robots start: 2 mm of difference can change the split (and
the first pose a robot reports is off its spawn pose by that much). A robot that reports within
``SNAP_M`` of a start pose the world gives for the expected fleet is planned from that pose, so
the same world and fleet size give the same plan run after run.
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np

from fleet.params import FleetConfig
from fleet.world import World
from planners.coverage import plan_coverage

PLAN_RESOLUTION = 0.025
SNAP_M = 0.05

log = logging.getLogger("coordinator")


class CoveragePlanner:
    """Plans coverage paths on the known floor plan for the robots present."""

    def __init__(self, world: World, cfg: FleetConfig, expected: int) -> None:
        self.grid = world.grid(PLAN_RESOLUTION)
        self.spawns = np.array([p[:2] for p in world.start_poses(expected, cfg.robot.radius)])
        # Paths keep wall_clearance more than the robot radius from obstacles: the DWA needs
        # clearance above the radius plus the noise of a median-filtered scan. Lanes overlap by
        # lane_overlap, as a real robot tracks its lane only to a few centimetres.
        self.params = dataclasses.replace(
            cfg.coverage,
            robot_radius=cfg.robot.radius + cfg.coordinator.wall_clearance,
            overlap=cfg.coordinator.lane_overlap,
            cleaning_width=cfg.robot.cleaning_width,
            max_speed=cfg.robot.max_vel_x,
        )

    def plan(self, starts: dict[str, tuple[float, float]]) -> dict[str, np.ndarray]:
        ids = list(starts)
        result = plan_coverage(self.grid, [self.snapped(starts[r]) for r in ids], self.params)
        m = result.metrics
        # judged on the plan's own floor: centres kept radius + wall clearance from obstacles
        log.info(
            "plan: coverage %.1f %%, repetition %.1f %%, %.1f m, est. makespan %.0f s",
            100 * m.total.coverage,
            100 * m.total.repetition,
            m.total.path_length_m,
            m.makespan_s,
        )
        return {rid: np.asarray(result.paths[i], dtype=float) for i, rid in enumerate(ids)}

    def snapped(self, xy: tuple[float, float]) -> tuple[float, float]:
        """The world's start pose within ``SNAP_M`` of ``xy`` (the nearest), else ``xy``."""
        d = np.hypot(*(self.spawns - np.asarray(xy, dtype=float)).T)
        if d.min() > SNAP_M:
            return xy
        x, y = self.spawns[int(np.argmin(d))]
        return float(x), float(y)
