"""How the coordinator turns the floor plan and the robots' start positions into paths.

For now one coverage plan splits the cleanable area into per-robot sets of regions
(``planners.coverage.plan_coverage``: boustrophedon decomposition, balanced split, ordered
sweeps). Auctions and space-time deconfliction replace this behind the same ``plan`` call.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from fleet.params import FleetConfig
from fleet.world import World


class CoveragePlanner:
    """Plans coverage paths on the known floor plan for the robots present."""

    def __init__(self, world: World, cfg: FleetConfig) -> None:
        self.cfg = cfg
        self.grid = world.grid(cfg.coverage.resolution)
        # Lanes keep this much more than the robot radius from walls: the DWA needs clearance
        # above the radius plus the noise of a median-filtered scan.
        self.params = dataclasses.replace(
            cfg.coverage,
            robot_radius=cfg.robot.radius + cfg.coordinator.wall_clearance,
            cleaning_width=cfg.robot.cleaning_width,
        )

    def plan(self, starts: dict[str, tuple[float, float]]) -> dict[str, np.ndarray]:
        from planners.coverage import plan_coverage

        ids = list(starts)
        result = plan_coverage(self.grid, [starts[r] for r in ids], self.params)
        return {rid: np.asarray(result.paths[i], dtype=float) for i, rid in enumerate(ids)}
