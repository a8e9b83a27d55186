"""Following a wall on the lidar at a set distance: the edge pass of a cleaning robot.

A robot vacuum cleans the band along walls and furniture by driving beside them at a set
distance, steered by its range sensor rather than by a planned path: its pose estimate is
centimetres off, the wall is where the sensor sees it. This is a nearest-point wall follower
after Bemporad, Di Marco and Tesi, "Wall-following controllers for sonar-based mobile robots"
(CDC 1997): the robot keeps the nearest obstacle point on its wall side at bearing ±90° and at
range ``distance``.

With ``p`` that point in the robot frame (x forward, y left), range r and bearing φ, and ``s``
the side (+1 wall on the left, −1 on the right), the robot points ``toward`` the wall by
ψ = −s·(φ − s·π/2). It steers ψ to ψ* = atan(k_r·(r − distance)), clipped to ±``max_approach``,
so it closes on a wall it is too far from and backs off one it is too near, and turns with

    ω = s·k_ψ·(ψ* − ψ) + ω_ff,

a second-order loop in the distance error, e¨ + k_ψ·e˙ + k_ψ·k_r·v·e = 0 near the set point.
ω_ff = v·sin φ / r holds a *stationary* point at its bearing: where the wall ends ahead (an
outside corner) the robot circles its end at radius r. Along a wall that goes on, the nearest
point slides with the robot and needs no feed-forward; it fades in over ``corner_ramp`` as the
wall ahead runs out, so the turn does not start as a step the angular acceleration limit would
smear into an overshoot. An inside corner is handled apart: the speed is capped so
that the robot can stop ``front_margin`` short of anything in its corridor ahead, and once the
wall ahead is nearer than the set distance it turns in place, away from its wall, until the way
along the new wall is open. A wall that steps toward the robot ahead (a staircase of map cells
along a wall a few degrees off the map's axes) counts for the distance term as soon as it is
within ``lookahead``, and nearer the wall than the set distance the robot slows in proportion
to the gap left to contact: the nearest-point law alone meets such a step only once it is the
nearest point, too late to turn within the angular acceleration limit.

Everything is a pure function of the scan points and the velocity; no pose estimate is used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from planners.checks import require_non_negative, require_positive
from planners.robot import RobotSpec

# Returns scattered about their fitted line by more than this (rms, m) are no straight wall:
# about twice the median-filtered scan's noise.
LINE_RMS_M = 0.015
# Nearer the wall than the set distance, the speed falls in proportion to the gap left to
# contact, to this share of it at most: time to steer out before a step of the wall ahead.
CLOSE_SPEED = 0.3
# Returns ahead nearer than the set distance are a wall stepping toward the robot when they
# run this far (m) along its heading; a wall across its way has them all at one x.
STEP_RUN_M = 0.05
# What lies within this angle (rad) of straight ahead is in the robot's way, not beside it.
FRONT_SECTOR = math.pi / 4


@dataclass(frozen=True)
class WallFollowParams:
    """``distance``: robot centre to the wall (m); ``speed``: cruising speed (m/s);
    ``gain_distance`` k_r (1/m) and ``gain_heading`` k_ψ (1/s) of the law above;
    ``max_approach``: largest angle (rad) at which the robot closes on or backs off the wall;
    ``reach``: points farther than this (m) are not the wall; ``front_margin``: the robot stops
    this far (m) short of an obstacle in its corridor ahead; ``corner_lookahead``: the wall has
    ended when it goes on no farther than this (m) past its nearest point, and the feed-forward
    fades in over the ``corner_ramp`` (m) before that; ``corner_speed``: speed (m/s) round an
    outside corner, braked down to at ``acc_lim_x`` as the wall ahead runs out; ``fit_radius``:
    the wall's line is fitted to the returns this near (m) its nearest one; ``wall_band``:
    returns within this (m) of that line's tangent count as the wall going on, up to
    ``horizon`` (m) ahead; ``lookahead``: the wall up to this far (m) ahead counts for the
    distance term where it is nearer than the set distance."""

    distance: float = 0.195
    speed: float = 0.2
    gain_distance: float = 3.0
    gain_heading: float = 3.0
    max_approach: float = 0.5
    reach: float = 0.45
    front_margin: float = 0.03
    corner_lookahead: float = 0.05
    corner_ramp: float = 0.05
    fit_radius: float = 0.12
    corner_speed: float = 0.1
    wall_band: float = 0.03
    horizon: float = 1.0
    lookahead: float = 0.3

    def validate(self) -> None:
        require_positive(
            self,
            "distance",
            "speed",
            "gain_distance",
            "gain_heading",
            "max_approach",
            "reach",
            "corner_lookahead",
            "corner_ramp",
            "fit_radius",
            "corner_speed",
            "wall_band",
            "horizon",
            "lookahead",
        )
        require_non_negative(self, "front_margin")
        if self.reach <= self.distance:
            raise ValueError("reach must be > distance")
        if self.max_approach >= math.pi / 2:
            raise ValueError("max_approach must be < pi/2")


@dataclass(frozen=True)
class WallFollowCommand:
    """The command, and whether the wall ``ends`` ahead (an outside corner being rounded)."""

    v: float
    w: float
    ends: bool


def to_robot_frame(points: np.ndarray, pose: tuple[float, float, float]) -> np.ndarray:
    """World points (N, 2) in the frame of a robot at ``pose`` (x forward, y left)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    d = np.asarray(points, dtype=float).reshape(-1, 2) - np.asarray(pose[:2])
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])


def nearest_wall_point(
    points: np.ndarray, side: int, reach: float, fit_radius: float = 0.0
) -> np.ndarray | None:
    """The nearest point of the wall on the ``side`` half-plane of ``points`` (robot frame)
    within ``reach``; None when no point is near.

    With ``fit_radius`` > 0 it is the foot of the perpendicular on the line fitted (total least
    squares) to the points within ``fit_radius`` of the nearest return, where that foot lies
    among them: the nearest of a few hundred noisy returns reads short by about a noise sigma,
    the fitted line does not. At a corner (the returns not on one line, or the foot outside
    them) the nearest return is kept."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    r = np.hypot(pts[:, 0], pts[:, 1])
    mine = (side * pts[:, 1] > 0) & (r <= reach)
    if not mine.any():
        return None
    near = pts[mine]
    p = near[np.argmin(r[mine])]
    if fit_radius > 0:
        local = near[np.hypot(*(near - p).T) <= fit_radius]
        if len(local) >= 3:
            centre = local.mean(axis=0)
            _, sv, vt = np.linalg.svd(local - centre, full_matrices=False)
            along = vt[0]
            foot = centre - float(centre @ along) * along
            extent = (local - centre) @ along
            straight = sv[1] / math.sqrt(len(local)) <= LINE_RMS_M
            if straight and extent.min() <= float((foot - centre) @ along) <= extent.max():
                p = foot
    return p


def wall_extent(
    points: np.ndarray, wall: np.ndarray, side: int, band: float, horizon: float
) -> float:
    """How far (m) the wall through its nearest point ``wall`` (robot frame) goes on ahead:
    the largest distance along the wall's tangent there (perpendicular to the ray to ``wall``,
    in the robot's direction of travel) of the ``points`` within ``band`` of that tangent line,
    capped at ``horizon``. Near 0 where the wall ends: an outside corner."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    ray = wall / max(float(np.hypot(*wall)), 1e-9)
    tangent = np.array([side * ray[1], -side * ray[0]])
    rel = pts - wall
    along, off = rel @ tangent, rel @ ray
    on = (np.abs(off) < band) & (along >= 0) & (along <= horizon)
    return float(along[on].max()) if on.any() else 0.0


def wall_ahead(points: np.ndarray, side: int, distance: float, lookahead: float) -> float:
    """The least distance (m) beside the robot's heading line of the ``points`` (robot frame)
    on the ``side`` up to ``lookahead`` ahead that are nearer that line than ``distance``, but
    not nearer than half of it (what lies nearer is in the robot's way, see
    :func:`front_gap`), where they run along the heading for ``STEP_RUN_M`` at least; inf
    otherwise. A wall that steps toward the robot ahead (a map's staircase of cells along a
    wall a few degrees off its axes) is steered away from before the robot reaches the step,
    not when the step is already its nearest point; a wall across the way ahead (the end of a
    lane) is left to :func:`front_gap`, so the robot keeps to its wall up to that corner."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    beside = side * pts[:, 1]
    ahead = (
        (pts[:, 0] > 0) & (pts[:, 0] <= lookahead) & (beside >= distance / 2) & (beside < distance)
    )
    if not ahead.any() or np.ptp(pts[ahead, 0]) < STEP_RUN_M:
        return math.inf
    return float(beside[ahead].min())


def front_gap(points: np.ndarray, robot_radius: float, sector: float = FRONT_SECTOR) -> float:
    """Free distance (m) straight ahead before the robot's disc touches one of ``points``
    (robot frame): the least x − √(R² − y²) over the points in its corridor |y| < R, x > 0,
    within ``sector`` (rad) of straight ahead. Returns farther round are the wall beside the
    robot, which the steering law keeps its distance from (a robot angled toward it would
    otherwise see it in its corridor and stop beside it)."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    ahead = (
        (pts[:, 0] > 0)
        & (np.abs(pts[:, 1]) < robot_radius)
        & (np.abs(np.arctan2(pts[:, 1], pts[:, 0])) <= sector)
    )
    if not ahead.any():
        return math.inf
    x, y = pts[ahead, 0], pts[ahead, 1]
    return float(np.min(x - np.sqrt(robot_radius**2 - y**2)))


def wall_follow_step(
    points: np.ndarray,
    side: int,
    velocity: tuple[float, float],
    params: WallFollowParams,
    robot: RobotSpec,
    dt: float,
    max_speed: float | None = None,
) -> WallFollowCommand | None:
    """One control step of the wall follower (see the module's docstring) for the disc
    ``robot``, within its speed and acceleration limits.

    ``points``: obstacle points in the robot frame; ``side``: +1 wall on the left, −1 on the
    right; ``max_speed``: a further cap on v (the caller's braking toward a stop). The speed is
    the least of the cruising speed, the robot's top speed, ``max_speed``, the speed from which
    the robot can still stop ``front_margin`` short of the nearest point in its corridor ahead
    (√(2·a·gap)) and the one from which it can brake to ``corner_speed`` where the wall ends,
    scaled by the cosine of the heading error and, nearer the wall than the set distance, by
    the share of the gap to contact left (at least ``CLOSE_SPEED``), all within the
    acceleration limits.
    None when no wall point lies within ``reach`` on that side.
    """
    if side not in (-1, 1):
        raise ValueError(f"side must be +1 (left) or -1 (right), not {side!r}")
    p = nearest_wall_point(points, side, params.reach, params.fit_radius)
    if p is None:
        return None
    extent = wall_extent(points, p, side, params.wall_band, params.horizon)
    ends = extent <= params.corner_lookahead
    robot_radius = robot.radius
    v_max, w_max = robot.max_vel_x, robot.max_vel_theta
    acc_v, acc_w = robot.acc_lim_x, robot.acc_lim_theta
    r = float(math.hypot(p[0], p[1]))
    bearing = math.atan2(p[1], p[0])
    toward = -side * math.remainder(bearing - side * math.pi / 2, 2 * math.pi)
    nearest = min(r, wall_ahead(points, side, params.distance, params.lookahead))
    wanted = max(
        -params.max_approach,
        min(params.max_approach, math.atan(params.gain_distance * (nearest - params.distance))),
    )
    error = wanted - toward
    gap = front_gap(points, robot_radius) - params.front_margin
    beyond = max(extent - params.corner_lookahead, 0.0)
    corner = math.sqrt(params.corner_speed**2 + 2 * acc_v * beyond)
    v = min(params.speed, v_max, corner, math.sqrt(2 * acc_v * max(gap, 0.0)))
    if max_speed is not None:
        v = min(v, max_speed)
    v *= max(0.0, math.cos(min(abs(error), math.pi / 2)))
    room = max(params.distance - robot_radius, 1e-3)
    v *= min(1.0, max(CLOSE_SPEED, (nearest - robot_radius) / room))
    v0, w0 = velocity
    v = min(max(v, v0 - acc_v * dt), v0 + acc_v * dt)
    v = max(v, 0.0)
    rounding = max(0.0, 1.0 - beyond / params.corner_ramp)
    feed = rounding * v * math.sin(bearing) / max(r, 1e-3)
    w = side * params.gain_heading * error + feed
    if gap <= params.distance - robot_radius:
        w = -side * w_max  # an inside corner: the wall ahead is nearer than the set distance
    w = min(max(w, w0 - acc_w * dt), w0 + acc_w * dt)
    w = min(max(w, -w_max), w_max)
    return WallFollowCommand(v, w, ends)
