"""Tracking a planned path with a differential-drive robot: the speed profile and the steering law.

The plan's sweeps are polylines: straight lanes, the short hops of their U-turns and the
connecting moves between groups of lanes. A robot drives them as the plan prices them
(:mod:`planners.drive_time`): it comes to rest exactly on every *stop* (a vertex where the path
turns by more than the plan's turn angle, and the path's end), turns in place there onto the
next segment, and drives each run between stops at full speed, braking into the next stop at
the robot's acceleration limit and slowing at the gentle vertices in between to what a
lateral-acceleration limit allows.

- The speed is the largest from which the robot can still brake to the speed allowed at the
  next vertex, v = √(v_next² + 2·a·d), d the distance along the path to it (the admissible
  velocity of Fox et al. 1997, applied to the profile's stops as to obstacles), capped at
  ``max_vel_x`` and at ``v_max · cos(heading error)``.
- The steering is Samson's path-following law (Samson, IEEE TAC 1995; the straight-segment case
  of Kanayama et al., ICRA 1990): with e the signed distance to the left of the segment and
  θ̃ the heading error, ω = −v·(k_y·e·sinc θ̃ + k_θ·sin θ̃), which makes e'' + k_θ·e' + k_y·e = 0
  along the arc length for small errors: critically damped at k_θ = 2√k_y.
- A vertex the path passes through is rounded by the arc tangent to both segments that passes
  ``corner_deviation`` from it; its speed is capped at √(lateral_acc · R) and max_vel_theta · R
  for that arc's radius R.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from planners.checks import require_non_negative, require_positive
from planners.polyline import LINE_M, simplify_indices
from planners.robot import RobotSpec


@dataclass(frozen=True)
class TrackerParams:
    """The path tracker's gains and limits (configs/fleet.yaml ``tracker:``).

    - ``gain_lateral`` k_y (1/m²): Samson's law's lateral gain, per metre of travel (so the
      response does not depend on the speed); its heading gain k_θ = 2·√k_y (1/m,
      :attr:`gain_heading`) damps it critically.
    - ``lateral_acc`` (m/s²): the centripetal acceleration allowed through a vertex.
    - ``corner_deviation`` (m): how far from a vertex driven through the rounded path may pass.
    - ``stop_tolerance`` (m): a stop is reached this close to it along the segment.
    - ``heading_tolerance`` (rad): the turn in place onto a segment ends this near its heading.
    - ``turn_heading`` (rad): a robot at rest on a stop turns in place onto the next segment
      when it heads farther off it than this (and then to within ``heading_tolerance``); nearer,
      Samson's law takes the rest out as it drives.
    - ``creep_speed`` (m/s): the least speed commanded short of a stop, so the last millimetres
      of the braking are driven, not approached for ever.
    - ``check_margin`` (m): the gap the braking arc of a command must keep between the body and
      the scan's points (and the peers' discs); where the robot is nearer already, it may not
      come nearer by more than the scan's noise, so that a lane planned beside a wall
      (``coordinator.wall_clearance`` from it) is driven at speed. As DWA's ``safety_margin``:
      at a convex corner the nearest scan point errs outward.
    - ``clear_ahead`` (m): the plan's path ahead must be that clear, by ``check_margin``, this
      much beyond where the robot can stop: a peer or a box on the lane ahead hands the robot to
      DWA before it has to brake hard, not when it stands at the obstacle.
    - ``rejoin_distance`` (m) and ``rejoin_heading`` (rad): the tracker drives only a robot this
      near its segment and heading this near it; farther off (after a detour round an
      obstacle), the local planner brings it back first.
    """

    gain_lateral: float = 16.0
    lateral_acc: float = 0.5
    corner_deviation: float = 0.01
    stop_tolerance: float = 0.005
    heading_tolerance: float = 0.02
    turn_heading: float = 0.1
    creep_speed: float = 0.02
    check_margin: float = 0.01
    clear_ahead: float = 0.1
    rejoin_distance: float = 0.15
    rejoin_heading: float = 0.6

    @property
    def gain_heading(self) -> float:
        """Samson's law's heading gain k_θ (1/m): critically damped with ``gain_lateral``."""
        return 2.0 * math.sqrt(self.gain_lateral)

    def validate(self) -> None:
        require_positive(
            self,
            "gain_lateral",
            "lateral_acc",
            "corner_deviation",
            "stop_tolerance",
            "heading_tolerance",
            "turn_heading",
            "creep_speed",
            "rejoin_distance",
            "rejoin_heading",
        )
        require_non_negative(self, "check_margin", "clear_ahead")


def turn_angles(points: np.ndarray) -> np.ndarray:
    """The heading change (rad, ≥ 0) at each vertex of a polyline; 0 at its two ends and where
    a segment has no length."""
    pts = np.asarray(points, dtype=float)
    out = np.zeros(len(pts))
    if len(pts) < 3:
        return out
    d = np.diff(pts, axis=0)
    heading = np.arctan2(d[:, 1], d[:, 0])
    change = np.abs(np.angle(np.exp(1j * np.diff(heading))))
    moved = np.hypot(*d.T) > 1e-9
    out[1:-1] = np.where(moved[:-1] & moved[1:], change, 0.0)
    return out


def corner_radii(points: np.ndarray, stop_angle: float, params: TrackerParams) -> np.ndarray:
    """The radius of the arc that rounds each vertex the path is driven through: tangent to
    both segments, passing ``corner_deviation`` from the vertex, R = δ·cos(θ/2)/(1 − cos(θ/2))
    for a turn θ, and no longer on either segment than half of it; 0 at the ends, at stops
    (turns over ``stop_angle``) and where the path runs straight on."""
    pts = np.asarray(points, dtype=float)
    turn = turn_angles(pts)
    radii = np.zeros(len(pts))
    bent = (turn > 1e-6) & (turn <= stop_angle)
    if len(pts) < 3 or not bent.any():
        return radii
    seg = np.hypot(*np.diff(pts, axis=0).T)
    room = np.minimum(seg[:-1], seg[1:]) / 2  # per interior vertex
    half = turn[1:-1] / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        r = params.corner_deviation * np.cos(half) / (1.0 - np.cos(half))
        r = np.minimum(r, room / np.tan(half))
    radii[1:-1] = np.where(bent[1:-1], r, 0.0)
    return radii


def turn_time(angle: np.ndarray, robot: RobotSpec) -> np.ndarray:
    """The least time to change the heading by ``angle`` from and to a constant heading, under
    ``max_vel_theta`` and ``acc_lim_theta`` (bang-bang, with a cruise when the angle allows)."""
    a = np.abs(np.asarray(angle, dtype=float))
    w, alpha = robot.max_vel_theta, robot.acc_lim_theta
    return np.where(a >= w * w / alpha, a / w + w / alpha, 2.0 * np.sqrt(a / alpha))


@dataclass(frozen=True, eq=False)
class Profile:
    """A path's plan for the tracker, from waypoint ``kept[0]`` on.

    The path is tracked as its Ramer–Douglas–Peucker simplification (the plan's
    ``coverage.simplify_tolerance``, as its time estimates see it: a staircase of grid steps
    along a slanted wall is one line, not a dozen stops; a line of the plan is not moved,
    ``planners.polyline.LINE_M``): ``kept`` (M) are the indices of the
    waypoints it keeps, ``segment`` (N) for each waypoint i the simplified segment k (from
    vertex k − 1 to k) that the path's segment into i lies on (0 before ``kept[0]``). At each
    kept vertex: the rounding radius (:func:`corner_radii`), and the speed of the time-optimal
    braking profile (the backward pass, v_k = min(cap_k, √(v_{k+1}² + 2·a·|p_{k+1} − p_k|)),
    with the cap 0 at the ends and at stops; on a rounded vertex √(lateral_acc·R),
    max_vel_theta·R, and the speed that drives the arc's two tangent lengths in the least time
    the heading can turn through it, :func:`turn_time`: the turn rate cannot step to v/R)."""

    kept: np.ndarray
    segment: np.ndarray
    radii: np.ndarray
    speeds: np.ndarray

    @classmethod
    def of(
        cls,
        points: np.ndarray,
        start: int,
        stop_angle: float,
        tolerance: float,
        params: TrackerParams,
        robot: RobotSpec,
    ) -> Profile:
        pts = np.asarray(points, dtype=float)
        start = min(max(start, 0), max(len(pts) - 1, 0))
        kept = start + simplify_indices(pts[start:], tolerance, LINE_M)
        segment = np.zeros(len(pts), dtype=np.int64)
        if len(kept) > 1:
            segment[start + 1 :] = np.searchsorted(kept, np.arange(start + 1, len(pts)))
        simple = pts[kept]
        radii = corner_radii(simple, stop_angle, params)
        caps = np.full(len(simple), robot.max_vel_x)
        turn = turn_angles(simple)
        caps[turn > stop_angle] = 0.0
        round_ = radii > 0
        r, theta = radii[round_], turn[round_]
        caps[round_] = np.minimum.reduce(
            [
                caps[round_],
                np.sqrt(params.lateral_acc * r),
                robot.max_vel_theta * r,
                2 * r * np.tan(theta / 2) / turn_time(theta, robot),
            ]
        )
        if len(caps):
            caps[0] = caps[-1] = 0.0
        seg = np.hypot(*np.diff(simple, axis=0).T) if len(simple) > 1 else np.zeros(0)
        v = caps
        for k in range(len(v) - 2, -1, -1):
            v[k] = min(v[k], math.sqrt(v[k + 1] ** 2 + 2.0 * robot.acc_lim_x * seg[k]))
        return cls(kept, segment, radii, v)

    def vertex(self, i: int) -> int:
        """The simplified vertex that waypoint ``i`` is, or −1."""
        k = int(np.searchsorted(self.kept, i))
        return k if k < len(self.kept) and self.kept[k] == i else -1

    def is_stop(self, i: int) -> bool:
        """Whether the robot comes to rest on waypoint ``i``."""
        k = self.vertex(i)
        return k >= 0 and self.speeds[k] == 0.0

    def tangent(self, points: np.ndarray, k: int) -> float:
        """How far before and after simplified vertex ``k`` its rounding arc leaves the
        segments (m); 0 where it is not rounded."""
        r = float(self.radii[k])
        if r <= 0 or not 0 < k < len(self.kept) - 1:
            return 0.0
        turn = turn_angles(points[self.kept[k - 1 : k + 2]])[1]
        return r * math.tan(float(turn) / 2)


@dataclass(frozen=True)
class Frenet:
    """The robot against segment a→b: ``along`` its projection's distance from a, ``left`` its
    signed distance to the left of the line, ``heading`` its heading error (rad, robot minus
    segment), and ``length`` the segment's length."""

    along: float
    left: float
    heading: float
    length: float
    curvature: float = 0.0

    @classmethod
    def of(cls, pose: tuple[float, float, float], a: np.ndarray, b: np.ndarray) -> Frenet:
        seg = np.asarray(b, dtype=float) - np.asarray(a, dtype=float)
        length = float(np.hypot(*seg))
        u = seg / length if length > 1e-12 else np.array([math.cos(pose[2]), math.sin(pose[2])])
        rel = np.array(pose[:2]) - np.asarray(a, dtype=float)
        along = float(rel @ u)
        left = float(u[0] * rel[1] - u[1] * rel[0])
        heading = math.remainder(pose[2] - math.atan2(u[1], u[0]), 2 * math.pi)
        return cls(along, left, heading, length)

    def on_arc(
        self,
        pose: tuple[float, float, float],
        a: np.ndarray,
        b: np.ndarray,
        c: np.ndarray,
        radius: float,
    ) -> Frenet:
        """The robot against the arc of ``radius`` that rounds vertex b between a→b and b→c
        (``along`` and ``length`` kept from the segment), its curvature signed (left turns +)."""
        u1 = (b - a) / np.hypot(*(b - a))
        u2 = (c - b) / np.hypot(*(c - b))
        sign = 1.0 if u1[0] * u2[1] - u1[1] * u2[0] > 0 else -1.0
        half = math.acos(max(-1.0, min(1.0, float(u1 @ u2)))) / 2
        start = b - u1 * radius * math.tan(half)
        centre = start + sign * radius * np.array([-u1[1], u1[0]])
        rel = np.array(pose[:2]) - centre
        d = float(np.hypot(*rel))
        tangent = math.atan2(rel[1], rel[0]) + sign * math.pi / 2
        heading = math.remainder(pose[2] - tangent, 2 * math.pi)
        return Frenet(self.along, sign * (radius - d), heading, self.length, sign / radius)


def samson_turn_rate(v: float, error: Frenet, params: TrackerParams) -> float:
    """Samson's path-following law: ω = v·κ·cos θ̃/(1 − κ·e) − v·(k_y·e·sinc θ̃ + k_θ·sin θ̃),
    κ the path's curvature at the robot's projection (0 on a segment; see the module)."""
    th, e, kappa = error.heading, error.left, error.curvature
    sinc = math.sin(th) / th if abs(th) > 1e-9 else 1.0
    feed = v * kappa * math.cos(th) / max(1.0 - kappa * e, 0.1) if kappa else 0.0
    return feed - v * (params.gain_lateral * e * sinc + params.gain_heading * math.sin(th))


def track_speed(
    short: float,
    heading: float,
    v_end: float,
    v_now: float,
    dt: float,
    params: TrackerParams,
    robot: RobotSpec,
) -> float:
    """The speed along the segment: the braking profile into its end, where ``v_end`` is
    allowed (0 at a stop; :class:`Profile`), ``short`` metres ahead, for the next control
    period ``dt``.

    The robot's speed moves from ``v_now`` toward the command v at up to ``acc_lim_x`` within
    the period and covers about (v_now + v)·dt/2 in it; the command is the largest v from which
    it can still brake to ``v_end`` in what is left after that:
    v² + a·dt·v + a·dt·v_now − v_end² − 2·a·d ≤ 0, with d the distance to the segment's end
    less v_now·dt/2: the speed a command is judged from is older than the command's effect by
    about half a period (the odometry's age and the wait for the next scan; in the simulator
    the robot stopped 15 mm past its stops without it and 2 mm short with it). At least
    ``creep_speed`` short of a stop, so the last millimetres are driven; scaled by the cosine
    of the heading error."""
    a = robot.acc_lim_x
    v0 = max(v_now, 0.0)
    c = a * dt * v0 - v_end**2 - 2 * a * max(short - v0 * dt / 2, 0.0)
    v = (-a * dt + math.sqrt(max((a * dt) ** 2 - 4 * c, 0.0))) / 2
    v = min(robot.max_vel_x, max(v, 0.0))
    if v_end == 0.0 and short > params.stop_tolerance:
        v = max(v, min(params.creep_speed, short / dt))
    return max(0.0, v * math.cos(heading))


def turn_rate(heading_error: float, w_now: float, dt: float, robot: RobotSpec) -> float:
    """The turn rate in place that brakes onto the heading: the largest from which the robot
    can still stop on it under ``acc_lim_theta`` after the next control period, judged as
    :func:`track_speed` judges the speed, with the sign of the error."""
    alpha = robot.acc_lim_theta
    err = abs(heading_error)
    w0 = w_now if heading_error > 0 else -w_now
    c = alpha * dt * max(w0, 0.0) - 2 * alpha * err
    rate = (-alpha * dt + math.sqrt(max((alpha * dt) ** 2 - 4 * c, 0.0))) / 2
    return math.copysign(min(robot.max_vel_theta, max(rate, 0.0)), heading_error)


def braking_arc(
    pose: tuple[float, float, float],
    v: float,
    w: float,
    v_now: float,
    dt: float,
    accel: float,
    spacing: float,
) -> np.ndarray:
    """Points (K, 2) at most ``spacing`` apart of the arc the robot drives when it holds the
    curvature of (v, ω) for the control period ``dt`` (covering about (v_now + v)·dt/2) and then
    brakes from v at ``accel`` (v²/(2·accel) more): the trajectory on which Fox et al. (1997)
    judge a velocity admissible, with the period before the next command can brake.
    Empty at v ≤ 0."""
    if v <= 0:
        return np.zeros((0, 2))
    length = (max(v_now, 0.0) + v) / 2 * dt + v * v / (2 * accel)
    s = np.linspace(0.0, length, max(2, math.ceil(length / spacing) + 1))[1:]
    kappa = w / v
    half = kappa * s / 2
    chord = s * np.sinc(half / np.pi)
    heading = pose[2] + half
    return np.column_stack([pose[0] + chord * np.cos(heading), pose[1] + chord * np.sin(heading)])
