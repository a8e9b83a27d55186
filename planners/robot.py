"""The robot the fleet drives, described once.

The ``robot:`` section of configs/fleet.yaml loads into a :class:`RobotSpec` (fleet.params),
which is passed to whoever needs the robot's size, brush or limits: DWA, the wall follower,
the agent's follower, coverage planning and the auction's task times, the simulator and the
benches. It has no defaults: the robot's numbers live in the config and nowhere else.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

from planners.checks import require_positive


@dataclass(frozen=True)
class RobotSpec:
    """A disc robot with differential drive.

    ``radius`` (m) of its body; ``wheel_base`` (m) between its wheels; ``cleaning_width`` (m)
    of its brush swath, centred on the robot and no wider than the body; ``max_vel_x`` (m/s)
    and ``max_vel_theta`` (rad/s) its top speeds, ``acc_lim_x`` (m/s²) and ``acc_lim_theta``
    (rad/s²) its acceleration limits (named as in ROS base_local_planner); ``mass`` (kg).
    """

    radius: float
    wheel_base: float
    cleaning_width: float
    max_vel_x: float
    max_vel_theta: float
    acc_lim_x: float
    acc_lim_theta: float
    mass: float

    def validate(self) -> None:
        require_positive(self, *(f.name for f in fields(self)))
        if self.cleaning_width > 2 * self.radius + 1e-9:
            raise ValueError("cleaning_width must not exceed the robot diameter (2·radius)")
