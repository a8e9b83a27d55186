"""How the coordinator turns the floor plan and the robots' start positions into paths.

For now the floor is split into one strip of equal area per robot, each swept by boustrophedon
lanes (``planners.lanes``). Region decomposition, auctions and space-time deconfliction replace
this behind the same ``plan`` call.
"""

from __future__ import annotations

import numpy as np

from fleet.params import FleetConfig
from fleet.world import World
from planners.lanes import LaneParams, plan_lanes

PLAN_RESOLUTION = 0.025


class CoveragePlanner:
    """Plans coverage paths on the known floor plan for the robots present."""

    def __init__(self, world: World, cfg: FleetConfig) -> None:
        self.grid = world.grid(PLAN_RESOLUTION)
        # Lanes keep wall_clearance more than the robot radius from obstacles: the DWA needs
        # clearance above the radius plus the noise of a median-filtered scan.
        self.params = LaneParams(
            robot_radius=cfg.robot.radius + cfg.coordinator.wall_clearance,
            cleaning_width=cfg.robot.cleaning_width,
            overlap=cfg.coordinator.lane_overlap,
        )

    def plan(self, starts: dict[str, tuple[float, float]]) -> dict[str, np.ndarray]:
        ids = list(starts)
        paths = plan_lanes(self.grid, [starts[r] for r in ids], self.params)
        return dict(zip(ids, paths, strict=True))
