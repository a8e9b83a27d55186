"""The sections of configs/fleet.yaml as frozen dataclasses, and the whole file.

``robot:`` is the one description of the robot (planners.robot.RobotSpec); the other sections
take their defaults from their dataclasses, which equal the values the file shows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, get_args

from fleet.config import ConfigError, configs_dir, from_mapping, read_yaml
from fleet.slam_params import SlamParams
from planners.checks import require_non_negative, require_positive
from planners.coverage.params import CoverageParams
from planners.dwa import DWAParams
from planners.robot import RobotSpec
from planners.tracking import TrackerParams
from planners.wall_follow import WallFollowParams

# how transits between tasks are kept apart: see fleet.coordinator.transits
DeconflictionMode = Literal["local", "prioritized", "cbs"]
DECONFLICTION_MODES: tuple[str, ...] = get_args(DeconflictionMode)


@dataclass(frozen=True)
class LidarParams:
    beams: int = 360
    fov: float = 2 * math.pi
    range_min: float = 0.1
    range_max: float = 6.0
    noise_sigma: float = 0.01
    rate_hz: float = 10.0

    def validate(self) -> None:
        require_positive(self, "beams", "rate_hz")
        require_non_negative(self, "noise_sigma")
        if not 0 < self.range_min < self.range_max:
            raise ValueError("need 0 < range_min < range_max")


@dataclass(frozen=True)
class OdometryParams:
    """Wheel odometry drift, as simulated by ``sim_server.odometry``.

    The odometry motion model of Thrun, Burgard, Fox, Probabilistic Robotics, §5.4 (rot1, trans,
    rot2), with noise *variances* growing linearly with distance and rotation, so the drift does
    not depend on the odometry rate and each alpha is an error std after one metre or radian:
    ``alpha_trans`` (m/√m) translation error per distance driven, ``alpha_rot`` (rad/√rad)
    heading error per angle turned, ``alpha_rot_trans`` (m/√rad) translation error per angle
    turned, ``alpha_trans_rot`` (rad/√m) heading error per distance driven; e.g. the heading
    error std after D metres straight is ``alpha_trans_rot·√D``. ``heading_bias_per_m`` is a
    systematic heading drift (rad per metre of signed travel, a wheel-size mismatch).
    """

    rate_hz: float = 50.0
    alpha_trans: float = 0.005
    alpha_rot: float = 0.005
    alpha_rot_trans: float = 0.002
    alpha_trans_rot: float = 0.003
    heading_bias_per_m: float = 0.001

    def validate(self) -> None:
        if not 1.0 <= self.rate_hz <= 200.0:
            raise ValueError("rate_hz must be within 1..200")
        require_non_negative(self, "alpha_trans", "alpha_rot", "alpha_rot_trans", "alpha_trans_rot")


@dataclass(frozen=True)
class SimParams:
    physics_hz: float = 100.0
    clock_hz: float = 20.0
    coverage_hz: float = 2.0
    cell_size: float = 0.05
    max_lag_s: float = 0.1
    agent_timeout_s: float = 10.0
    first_answer_timeout_s: float = 20.0

    def validate(self) -> None:
        if self.physics_hz < 20:
            raise ValueError("physics_hz must be >= 20")
        require_positive(
            self, "clock_hz", "coverage_hz", "cell_size", "max_lag_s", "agent_timeout_s"
        )
        if self.agent_timeout_s > self.first_answer_timeout_s:
            raise ValueError("agent_timeout_s must not exceed first_answer_timeout_s")


@dataclass(frozen=True)
class AgentParams:
    pose_source: Literal["slam", "odometry"] = "slam"
    map_hz: float = 1.0
    control_hz: float = 10.0
    stale_after_s: float = 0.5
    waypoint_tolerance: float = 0.15
    along_tolerance: float = 0.03
    goal_tolerance: float = 0.05
    give_up_after_s: float = 3.0
    give_way_max_s: float = 20.0
    align_enter: float = 0.6
    align_exit: float = 0.1
    align_lookahead: float = 0.3
    escape_after_s: float = 1.0
    escape_distance: float = 0.15
    escape_speed: float = 0.1
    intent_horizon_s: float = 2.0
    status_hz: float = 2.0
    heartbeat_hz: float = 5.0
    state_save_s: float = 2.0
    pose_save_s: float = 0.2
    transit_speed: float = 0.25
    hold_max_s: float = 30.0
    hold_silent_s: float = 2.0
    edge_slack: float = 0.05
    edge_window: float = 0.3
    edge_cover: float = 0.8
    edge_heading: float = 0.2
    edge_peer_clear: float = 1.0

    def validate(self) -> None:
        require_positive(
            self,
            "edge_slack",
            "edge_window",
            "edge_heading",
            "edge_peer_clear",
            "hold_max_s",
            "hold_silent_s",
            "map_hz",
            "status_hz",
            "heartbeat_hz",
            "state_save_s",
            "pose_save_s",
            "transit_speed",
            "stale_after_s",
            "give_up_after_s",
            "align_exit",
            "escape_after_s",
            "escape_distance",
            "escape_speed",
        )
        require_non_negative(self, "give_way_max_s")
        if not self.align_exit <= self.align_enter <= math.pi:
            raise ValueError("need 0 < align_exit <= align_enter <= pi")
        if not 0 < self.edge_cover <= 1:
            raise ValueError("edge_cover must be within (0, 1]")


@dataclass(frozen=True)
class CoordinatorParams:
    wall_clearance: float = 0.015
    lane_overlap: float = 0.1667
    expected_robots_grace_s: float = 20.0
    task_target_s: float = 20.0
    heartbeat_timeout_s: float = 1.0
    bid_timeout_s: float = 0.5
    deconfliction: DeconflictionMode = "local"
    replan_lag_s: float = 10.0
    body_margin: float = 0.05
    max_detour_m: float = 1.0
    stall_s: float = 30.0
    stall_progress_m: float = 0.1
    explore_every_s: float = 2.0
    explore_gain_s_per_m2: float = 2.0
    explore_min_gain_m2: float = 0.1
    explore_match_m: float = 0.5
    explore_step_m: float = 0.05
    map_check_every_s: float = 2.0
    map_change_confidence: float = 0.85
    map_change_min_size_m: float = 0.2
    map_change_wall_margin_m: float = 0.15
    map_change_robot_clear_m: float = 0.25

    def validate(self) -> None:
        require_non_negative(self, "explore_gain_s_per_m2", "explore_min_gain_m2")
        require_positive(
            self,
            "explore_every_s",
            "explore_match_m",
            "explore_step_m",
            "map_check_every_s",
            "task_target_s",
            "heartbeat_timeout_s",
            "bid_timeout_s",
            "replan_lag_s",
            "stall_s",
            "stall_progress_m",
            "max_detour_m",
        )
        require_non_negative(self, "body_margin", "wall_clearance")
        if not 0.0 <= self.lane_overlap < 0.9:
            # the coverage planner's own bound on the overlap it is given (CoverageParams)
            raise ValueError(f"lane_overlap must be within [0, 0.9), got {self.lane_overlap}")
        if not 0.5 < self.map_change_confidence < 1.0:
            raise ValueError(
                f"map_change_confidence must be within (0.5, 1), got {self.map_change_confidence}"
            )
        require_positive(
            self, "map_change_min_size_m", "map_change_wall_margin_m", "map_change_robot_clear_m"
        )


# Fields of other sections that copied the robot's numbers, and the robot: field each became.
# A config that still gives one is refused, so a copy cannot silently disagree with robot:.
MOVED_TO_ROBOT: dict[str, dict[str, str]] = {
    "dwa": {
        "max_vel_x": "max_vel_x",
        "max_vel_theta": "max_vel_theta",
        "acc_lim_x": "acc_lim_x",
        "acc_lim_theta": "acc_lim_theta",
    },
    "coverage": {
        "robot_radius": "radius",
        "cleaning_width": "cleaning_width",
        "max_speed": "max_vel_x",
        "max_accel": "acc_lim_x",
        "max_turn_rate": "max_vel_theta",
        "max_turn_accel": "acc_lim_theta",
    },
}


# Options removed once their alternative was measured and lost (or their value is derived): the
# code does what their default did. A config that still gives one is refused, naming it, rather
# than told it is unknown and offered a near name; git and BENCHMARKS.md keep why each went.
REMOVED: dict[str, tuple[str, ...]] = {
    "agent": ("edge_pass", "peer_margin", "swept_within"),
    "coordinator": ("first_regions", "objective", "sweep_freed_floor", "map_changes"),
    "tracker": ("gain_heading",),
    "dwa": ("path_aggregation",),
    "coverage": (
        "method",
        "edge_pass",
        "max_task_area",
        "skip_order",
        "neighbour_cuts",
        "return_strips",
    ),
}


@dataclass(frozen=True)
class FleetConfig:
    """The whole file: ``robot:`` must be given (every field), the other sections may be left
    out in whole or in part."""

    robot: RobotSpec
    lidar: LidarParams = field(default_factory=LidarParams)
    odometry: OdometryParams = field(default_factory=OdometryParams)
    sim: SimParams = field(default_factory=SimParams)
    agent: AgentParams = field(default_factory=AgentParams)
    coordinator: CoordinatorParams = field(default_factory=CoordinatorParams)
    dwa: DWAParams = field(default_factory=DWAParams)
    tracker: TrackerParams = field(default_factory=TrackerParams)
    wall_follow: WallFollowParams = field(default_factory=WallFollowParams)
    slam: SlamParams = field(default_factory=SlamParams)
    coverage: CoverageParams = field(default_factory=CoverageParams)

    def validate(self) -> None:
        if self.dwa.min_vel_x > self.robot.max_vel_x:
            raise ValueError(
                f"dwa.min_vel_x ({self.dwa.min_vel_x}) must not exceed robot.max_vel_x "
                f"({self.robot.max_vel_x})"
            )
        if self.wall_follow.distance <= self.robot.radius:
            raise ValueError(
                f"wall_follow.distance ({self.wall_follow.distance}) must exceed robot.radius "
                f"({self.robot.radius}): the robot would drive into the wall it follows"
            )


def default_config_path() -> Path:
    return configs_dir() / "fleet.yaml"


def load_fleet_config(path: str | Path | None = None) -> FleetConfig:
    """Load and validate ``configs/fleet.yaml`` (or ``path``); errors name file and field.

    The ``robot:`` section is required in full. A field that moved to it (see
    ``MOVED_TO_ROBOT``) is refused where it used to be, naming where it lives now; a removed
    option (``REMOVED``) is refused naming it.
    """
    p = Path(path) if path is not None else default_config_path()
    data = read_yaml(p)
    _refuse_gone(data, p)
    return from_mapping(FleetConfig, data, str(p))


def _refuse_gone(data: object, path: Path) -> None:
    """Refuse a key that moved to ``robot:`` (``MOVED_TO_ROBOT``) or was removed
    (``REMOVED``), saying which."""
    if not isinstance(data, dict):
        return
    gone = [
        (section, old, f"the robot's size and limits live in robot: (robot.{new})")
        for section, moved in MOVED_TO_ROBOT.items()
        for old, new in moved.items()
    ] + [
        (section, old, "no longer an option (the code always does what its default did)")
        for section, removed in REMOVED.items()
        for old in removed
    ]
    for section, old, why in gone:
        given = data.get(section)
        if isinstance(given, dict) and old in given:
            raise ConfigError(f"{path}: {section}.{old}: {why}; remove {section}.{old}")
