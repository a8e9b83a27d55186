"""The robot the pure tests drive: the robot: section of configs/fleet.yaml written out, so a
test of a planner needs no config file (tests/fleet/test_config.py checks that they agree)."""

from __future__ import annotations

from planners.robot import RobotSpec

ROBOT = RobotSpec(
    radius=0.17,
    wheel_base=0.3,
    cleaning_width=0.30,
    max_vel_x=0.5,
    max_vel_theta=1.0,
    acc_lim_x=0.5,
    acc_lim_theta=1.0,
    mass=3.5,
)
