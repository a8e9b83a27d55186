"""What the path follower remembers between steps, what it sees in one, and its parameters."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fleet.params import AgentParams, FleetConfig
from planners.dwa import DWAParams
from planners.robot import RobotSpec
from planners.tracking import Profile, TrackerParams
from planners.wall_follow import WallFollowParams

Pose = tuple[float, float, float]


@dataclass(frozen=True)
class FollowState:
    waypoints: np.ndarray
    index: int = 0
    stalled_s: float = 0.0
    best_dist: float = math.inf
    aligning: bool = False
    best_error: float = math.inf
    blocked_s: float = 0.0
    escape_m: float = 0.0
    escape_heading: float = 0.0
    escape_sign: int = 1
    skipped: int = 0
    yielded_s: float = 0.0
    edge_side: int = 0
    # waypoints given up farther than the brush's reach (half robot.cleaning_width) from them:
    # their pieces are unswept
    missed: tuple[int, ...] = ()
    # a waypoint to come to rest on, as on the last (the order of passage holds the robot
    # before the one after it); -1: none
    stop_at: int = -1
    # the path tracker (agents.follow.track) drives the segments into the waypoints after this
    # one (the plan's sweeps) by ``profile``, the path's speeds and rounded corners; None: DWA
    track_from: int | None = None
    profile: Profile | None = None

    @property
    def done(self) -> bool:
        return self.index >= len(self.waypoints)

    @property
    def tracked(self) -> bool:
        """Whether the segment into the next waypoint is the tracker's."""
        return (
            self.track_from is not None
            and self.profile is not None
            and self.track_from < self.index < len(self.waypoints)
        )

    def at(
        self, index: int, skipped: int | None = None, missed: tuple[int, ...] | None = None
    ) -> FollowState:
        """The same path and what it keeps along it, heading for waypoint ``index`` afresh."""
        return FollowState(
            self.waypoints,
            index,
            skipped=self.skipped if skipped is None else skipped,
            missed=self.missed if missed is None else missed,
            stop_at=self.stop_at,
            track_from=self.track_from,
            profile=self.profile,
        )


@dataclass(frozen=True, eq=False)
class Situation:
    """What one step sees: the robot's ``pose`` and ``velocity`` (v, ω), the world-frame
    obstacle points of its scan, ``peers``, the centres of the discs the robots it gives
    way to will cover (:func:`agents.peers.intent_centres`), and ``everyone``'s."""

    pose: Pose
    velocity: tuple[float, float]
    obstacles: np.ndarray
    peers: np.ndarray
    # the centres of the discs every live peer will cover, whoever gives way (the tracker
    # leaves the driving to DWA and its give-way near any of them)
    everyone: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))


@dataclass(frozen=True)
class FollowParams:
    """Everything the follower is tuned by, built once from the config (:meth:`of`): DWA's
    parameters, the robot, the agent's, the wall follower's (None, for scenes that test the
    rest alone: no edge pass), the control period ``dt`` (s), the path tracker's, the turn
    (rad) beyond which a vertex of the plan is a stop and the tolerance (m) of the
    simplification the tracker drives."""

    dwa: DWAParams
    robot: RobotSpec
    agent: AgentParams
    wall: WallFollowParams | None
    dt: float
    tracker: TrackerParams = field(default_factory=TrackerParams)
    stop_angle: float = math.radians(45.0)
    simplify_tolerance: float = 0.03

    @classmethod
    def of(cls, cfg: FleetConfig) -> FollowParams:
        """The control period is the scan period: one step per scan. The tracker drives the
        path as the plan's time estimates see it: simplified by ``coverage.simplify_tolerance``,
        stopping to turn where it turns by more than ``coverage.turn_angle_deg`` (a
        simplification that cuts a corner is caught by the tracker's check, and DWA drives it)."""
        return cls(
            cfg.dwa,
            cfg.robot,
            cfg.agent,
            cfg.wall_follow,
            1.0 / cfg.lidar.rate_hz,
            cfg.tracker,
            math.radians(cfg.coverage.turn_angle_deg),
            cfg.coverage.simplify_tolerance,
        )
