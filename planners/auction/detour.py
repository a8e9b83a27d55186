"""Tasks made from parts of a task: the drivable runs of a path repaired around a lost robot's
body (:func:`planners.bodies.reroute`) and the stretches under or behind it."""

from __future__ import annotations

import numpy as np

from planners.auction.tasks import Task, task_time
from planners.coverage.params import CoverageParams
from planners.polyline import path_length
from planners.robot import RobotSpec


def part_of(
    task: Task, path: np.ndarray, new_id: str, params: CoverageParams, robot: RobotSpec
) -> Task:
    """A task driving ``path``, a part of ``task``'s path (possibly with a detour of its own):
    its area is ``task``'s scaled by the share of its length (at most all of it), its time
    recomputed for ``robot``, its cells ``task``'s."""
    whole = path_length(task.path)
    share = min(1.0, path_length(path) / whole) if whole > 0 else 1.0
    return Task(
        new_id, path, task.area_m2 * share, task_time(path, params, robot), task.cells, task.kind
    )
