"""What the path follower remembers between steps, what it sees in one, and its parameters."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fleet.params import AgentParams, FleetConfig
from planners.dwa import DWAParams
from planners.robot import RobotSpec
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
    # waypoints given up farther than agent.swept_within from them: their pieces are unswept
    missed: tuple[int, ...] = ()
    # a waypoint to come to rest on, as on the last (the order of passage holds the robot
    # before the one after it); -1: none
    stop_at: int = -1

    @property
    def done(self) -> bool:
        return self.index >= len(self.waypoints)


@dataclass(frozen=True, eq=False)
class Situation:
    """What one step sees: the robot's ``pose`` and ``velocity`` (v, ω), the world-frame
    obstacle points of its scan, and ``peers``, the centres of the discs the robots it gives
    way to will cover (:func:`agents.peers.intent_centres`)."""

    pose: Pose
    velocity: tuple[float, float]
    obstacles: np.ndarray
    peers: np.ndarray


@dataclass(frozen=True)
class FollowParams:
    """Everything the follower is tuned by, built once from the config (:meth:`of`): DWA's
    parameters, the robot, the agent's, the wall follower's (None: no edge pass) and the
    control period ``dt`` (s)."""

    dwa: DWAParams
    robot: RobotSpec
    agent: AgentParams
    wall: WallFollowParams | None
    dt: float

    @classmethod
    def of(cls, cfg: FleetConfig) -> FollowParams:
        """The control period is the scan period: one step per scan."""
        wall = cfg.wall_follow if cfg.agent.edge_pass else None
        return cls(cfg.dwa, cfg.robot, cfg.agent, wall, 1.0 / cfg.lidar.rate_hz)
