"""Tunables of the coverage planner (the ``coverage:`` section of ``configs/fleet.yaml``)."""

from __future__ import annotations

from dataclasses import dataclass

from planners.checks import require_non_negative, require_positive
from planners.robot import RobotSpec


@dataclass(frozen=True)
class CoverageParams:
    """How to plan coverage paths for a robot (:class:`planners.robot.RobotSpec`, passed beside
    these: its radius, brush and limits are not copied here).

    Lanes are the robot's ``cleaning_width · (1 − overlap)`` apart. With ``fill_in`` the floor
    the sweeps miss is cleaned by targeted passes placed in the tour like any task, the most
    cells per metre first, until the sweeps and passes cover a little more than
    ``fill_in_target`` of the cleanable area; the final pruning then drops the tasks that cost
    the most driving per cell while at least ``fill_in_target`` stays covered (1.0: every pass,
    nothing lost). A dead-end room may get a lane along the wall where its lanes end (and lanes
    across its usual axis), so the way back to its door is sweeping rather than a transit. Rooms
    are separated at openings narrower than ``door_width``; a room smaller than
    ``min_room_area`` joins its largest neighbour. Every lane of a boustrophedon cell is a task
    of its own, cut into pieces of at most ``max_lane_length``, so the tour chooses the order
    and direction of every lane, can leave a cell part-swept to visit a neighbour and come back,
    and k robots can balance the work finely. Time estimates use the robot's top speed
    ``max_vel_x`` plus ``turn_cost_s`` per turn (a heading change over ``turn_angle_deg``); the
    market's tasks (``planners.auction.split_tour``) are timed by the robot's kinematics
    instead: a stop and a turn in place at each such turn (``max_vel_theta``, ``acc_lim_theta``)
    and rest-to-rest runs between them (``max_vel_x``, ``acc_lim_x``).
    """

    overlap: float = 0.0
    fill_in: bool = True
    fill_in_target: float = 0.995
    turn_cost_s: float = 2.0
    turn_angle_deg: float = 45.0
    door_width: float = 1.0
    min_room_area: float = 2.0
    max_lane_length: float = 1.25
    simplify_tolerance: float = 0.03

    def validate(self) -> None:
        require_positive(self, "door_width", "max_lane_length")
        require_non_negative(self, "turn_cost_s", "min_room_area", "simplify_tolerance")
        if not 0.0 <= self.overlap < 0.9:
            raise ValueError("overlap must be within [0, 0.9)")
        if not 0 < self.turn_angle_deg < 180:
            raise ValueError("turn_angle_deg must be within (0, 180)")
        if not 0.0 <= self.fill_in_target <= 1.0:
            raise ValueError("fill_in_target must be within [0, 1]")

    def lane_spacing(self, robot: RobotSpec) -> float:
        return robot.cleaning_width * (1.0 - self.overlap)
