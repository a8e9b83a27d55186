"""Dynamic Window Approach local planner (Fox, Burgard, Thrun 1997), vectorized rollouts."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class DWAParams:
    """Parameters named as in ROS base_local_planner / dwa_local_planner."""

    max_vel_x: float = 0.5
    min_vel_x: float = 0.0
    max_vel_theta: float = 1.0
    acc_lim_x: float = 0.5
    acc_lim_theta: float = 1.0
    sim_time: float = 1.5
    sim_granularity: float = 0.1
    vx_samples: int = 8
    vtheta_samples: int = 20
    path_distance_bias: float = 32.0
    goal_distance_bias: float = 24.0
    occdist_scale: float = 0.1
    safety_margin: float = 0.05
