"""Coverage planning: decomposition, coverage paths, ordering, splitting, metrics.

Public API::

    plan_coverage(grid: GridMap, starts: list[tuple[float, float]], params: CoverageParams,
                  robot: RobotSpec, *, wall_clearance: float) -> CoveragePlan
    coverage_metrics(grid, paths, robot_radius, cleaning_width, *, max_speed, turn_cost_s, ...)
        -> CoverageMetrics
    plan_metrics(grid, paths, params: CoverageParams, robot: RobotSpec, *,
                 wall_clearance: float, cleanable_mask=None) -> CoverageMetrics

``CoveragePlan`` holds per robot the (N, 2) waypoint path in world metres, the room and cell
label images, their networkx adjacency graphs, the cell → robot assignment, the metrics, and the
free space no robot can clean (``unreachable``, ``unreachable_area_m2``). Every definition the
metrics use is in :mod:`planners.coverage.metrics`.
"""

from planners.coverage.metrics import (
    CoverageMetrics,
    PathMetrics,
    coverage_metrics,
    plan_metrics,
)
from planners.coverage.params import CoverageParams
from planners.coverage.plan import CoveragePlan, PlanningError, plan_coverage

__all__ = [
    "CoverageMetrics",
    "CoverageParams",
    "CoveragePlan",
    "PathMetrics",
    "PlanningError",
    "coverage_metrics",
    "plan_coverage",
    "plan_metrics",
]
