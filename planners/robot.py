"""The robot the fleet drives, described once.

The ``robot:`` section of configs/fleet.yaml loads into a :class:`RobotSpec` (fleet.params),
which is passed to whoever needs the robot's size, brush or limits: DWA, the wall follower,
the agent's follower, coverage planning and the auction's task times, the simulator and the
benches. It has no defaults: the robot's numbers live in the config and nowhere else.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np

from planners.battery import BatterySpec
from planners.checks import require_positive

# A side brush reaching farther than this beyond the body (m) is no side brush a robot vacuum
# carries (theirs stick out a few centimetres); a config asking for more is a typo.
SIDE_BRUSH_MAX_OUT = 0.1


@dataclass(frozen=True)
class SideBrush:
    """A robot vacuum's side brush: a spinning disc of bristles at the front corner of the body
    that sweeps the floor beside and ahead of it into the main brush's path, so the band along
    walls the body keeps the main brush from is cleaned too.

    ``enabled``: whether the robot has one (off, the robot cleans with its main brush alone);
    ``reach`` (m): from the robot's centre to the bristles' outer edge; ``radius`` (m) of the
    bristles' disc; ``angle`` (rad): the bearing of the disc's centre from the heading,
    counter-clockwise, so a brush at the front right (as most robot vacuums carry theirs) has a
    negative angle.
    """

    enabled: bool = False
    reach: float = 0.22
    radius: float = 0.07
    angle: float = -1.0

    def validate(self) -> None:
        require_positive(self, "reach", "radius")
        if self.radius > self.reach:
            raise ValueError(f"radius ({self.radius}) must not exceed reach ({self.reach})")
        if not -math.pi <= self.angle <= math.pi:
            raise ValueError(f"angle ({self.angle}) must lie in [-pi, pi]")

    @property
    def side(self) -> int:
        """+1 when the brush sits on the left of the heading, -1 on the right."""
        return 1 if self.angle > 0 else -1

    def centres(self, poses: np.ndarray) -> np.ndarray:
        """(N, 2) world positions of the bristles' disc for (N, 3) robot poses (x, y, theta)."""
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        d = self.reach - self.radius
        bearing = poses[:, 2] + self.angle
        return poses[:, :2] + d * np.column_stack([np.cos(bearing), np.sin(bearing)])


@dataclass(frozen=True)
class RobotSpec:
    """A disc robot with differential drive.

    ``radius`` (m) of its body; ``wheel_base`` (m) between its wheels; ``cleaning_width`` (m)
    of its brush swath, centred on the robot and no wider than the body; ``max_vel_x`` (m/s)
    and ``max_vel_theta`` (rad/s) its top speeds, ``acc_lim_x`` (m/s²) and ``acc_lim_theta``
    (rad/s²) its acceleration limits (named as in ROS base_local_planner); ``mass`` (kg);
    ``side_brush`` its side brush (:class:`SideBrush`; none unless the config gives one);
    ``battery`` its battery (:class:`planners.battery.BatterySpec`; off unless the config turns
    it on: the robot never runs down).
    """

    radius: float
    wheel_base: float
    cleaning_width: float
    max_vel_x: float
    max_vel_theta: float
    acc_lim_x: float
    acc_lim_theta: float
    mass: float
    side_brush: SideBrush = field(default_factory=SideBrush)
    battery: BatterySpec = field(default_factory=BatterySpec)

    def validate(self) -> None:
        parts = ("side_brush", "battery")
        require_positive(self, *(f.name for f in fields(self) if f.name not in parts))
        if self.cleaning_width > 2 * self.radius + 1e-9:
            raise ValueError("cleaning_width must not exceed the robot diameter (2·radius)")
        brush = self.side_brush
        if brush.enabled and brush.reach > self.radius + SIDE_BRUSH_MAX_OUT + 1e-9:
            raise ValueError(
                f"side_brush.reach ({brush.reach}) must not exceed radius + {SIDE_BRUSH_MAX_OUT} "
                f"({self.radius + SIDE_BRUSH_MAX_OUT:.3f}): a side brush sticks out of the body "
                "by a few centimetres"
            )
        if brush.enabled and brush.reach <= self.cleaning_width / 2:
            raise ValueError(
                f"side_brush.reach ({brush.reach}) must exceed half cleaning_width "
                f"({self.cleaning_width / 2}): a side brush inside the main brush sweeps nothing"
            )
