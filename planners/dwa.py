"""Dynamic Window Approach local planner (Fox, Burgard, Thrun 1997), vectorized rollouts.

Follows ROS ``dwa_local_planner`` (with ``base_local_planner``'s trajectory generator and cost
functions): sample (v, ω) in the dynamic window reachable within one control period, roll each
sample out at constant velocity for ``sim_time``, discard the ones that come too close to an
obstacle, and score the rest by how well their end pose follows the given path. Everything is
vectorized over samples and time steps at once; obstacle clearance comes from one
``scipy.spatial.cKDTree`` query (measured about 10× faster than a dense numpy distance matrix for
360 obstacle points and ~1300 trajectory points; see BENCHMARKS.md, ``## fleet bench dwa``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from planners.checks import require_non_negative, require_positive
from planners.robot import RobotSpec

# Smallest body-to-obstacle gap used in the 1/gap obstacle cost: keeps the cost finite when a
# robot that already is closer than robot_radius + safety_margin (sensor noise) moves away.
_MIN_GAP = 1e-3
# The noise of the agent's 5-beam median's nearest point (m): how much nearer than it starts a
# robot already within robot_radius + safety_margin may come on its way out (the path tracker's
# check allows its commands the same). Down to the bare radius, as it was, a rollout passing a
# convex corner tangentially (nearer, then farther) was admitted on a scan that read the corner
# a few mm wide, and creeping past step by step touched it.
MEDIAN_NOISE_M = 0.005


@dataclass(frozen=True)
class DWAParams:
    """Parameters named as in ROS base_local_planner / dwa_local_planner.

    The robot's top speeds and acceleration limits (ROS's ``max_vel_x``, ``max_vel_theta``,
    ``acc_lim_x``, ``acc_lim_theta``) are not copied here: they are the robot's
    (:class:`planners.robot.RobotSpec`), passed beside these. ``min_vel_x`` is the planner's
    choice (0: it never samples reverse). ``sim_granularity`` is, as in ROS, the largest
    distance (m) between consecutive collision-checked points of a rollout. Fields added beyond
    the original set:

    - ``forward_point_distance`` (ROS dwa_local_planner, default 0.325 m): the "nose" point ahead
      of the trajectory's end that the alignment and goal-front costs score. Without it a robot
      at rest facing away from its path sees no benefit in rotating (every in-place rotation ends
      at the same position), so it could never turn around.
    - ``goal_lookahead`` (m): how far along the path, from the robot's projection onto it, the
      local goal lies. ROS takes the last path point inside the local costmap; a fixed lookahead
      gives the same pull without a costmap.
    - ``corner_angle`` (rad): path vertices turning more than this are stops. The local goal does
      not pass the next one until the robot is within ``sim_granularity`` of it, so the robot
      drives into a lane end and turns there instead of cutting across to the next lane (ROS has
      no equivalent; its global planner rarely makes such corners). Grid paths' 45° steps stay
      below the default and are cut smoothly.

    A rollout's distance from the path is averaged over its points, where ROS's path cost
    scores its end point only by default (its MapGridCostFunction offers a ``Sum`` aggregation
    for the same purpose), so an arc that ends on the path but bulges off it in between scores
    worse.

    ``safety_margin`` (default 0.01 m, the lidar's range noise σ) covers what the obstacle
    points miss at a convex corner: there the nearest obstacle is one point, seen by one or two
    beams, which no filter can average, and a 5-beam median moves it outward (the corner is a
    minimum of range over bearing). Beside a straight wall the nearest of many noisy points
    errs inward, so a zero margin is safe there, but at a corner it lets rollouts graze it.
    """

    min_vel_x: float = 0.0
    sim_time: float = 1.5
    sim_granularity: float = 0.1
    vx_samples: int = 8
    vtheta_samples: int = 20
    path_distance_bias: float = 32.0
    goal_distance_bias: float = 24.0
    occdist_scale: float = 0.1
    safety_margin: float = 0.01
    forward_point_distance: float = 0.325
    goal_lookahead: float = 1.0
    corner_angle: float = 1.0

    def validate(self) -> None:
        require_positive(self, "sim_time", "sim_granularity", "vx_samples", "vtheta_samples")
        require_non_negative(
            self,
            "min_vel_x",
            "path_distance_bias",
            "goal_distance_bias",
            "occdist_scale",
            "safety_margin",
            "forward_point_distance",
            "goal_lookahead",
            "corner_angle",
        )


@dataclass(frozen=True)
class DWAResult:
    """The chosen command and its predicted trajectory.

    ``trajectory`` rows are the poses (x, y, θ) at uniform times 0, h, 2h, …, sim_time with
    h = sim_time / (T − 1); row 0 is the current pose. ``admissible`` is False when the robot is
    blocked: no sampled trajectory that moves it forward is collision-free, or standing still
    short of the goal is best (see :func:`dwa_control`). (v, w) is then a safe fallback: brake as
    hard as the window allows along the current arc, or, once v = 0 is reachable, the best
    in-place rotation (collision-free for a disc robot) — which is a stop when rotating does not
    turn the robot toward its path. ``cost`` is inf when the fallback trajectory itself is not
    collision-free.
    """

    v: float
    w: float
    trajectory: np.ndarray
    cost: float
    admissible: bool


def dynamic_window(
    velocity: tuple[float, float],
    params: DWAParams,
    robot: RobotSpec,
    dt: float,
    speed: float | None = None,
) -> tuple[float, float, float, float]:
    """(v_lo, v_hi, w_lo, w_hi): the velocities reachable within ``dt`` under the robot's
    acceleration limits, clipped into [min_vel_x, max_vel_x] × [−max_vel_theta, max_vel_theta]
    (a current velocity outside the limits is commanded back to the nearest limit); with
    ``speed``, v is clipped to that one speed instead."""
    v0, w0 = velocity
    dv, dw = robot.acc_lim_x * dt, robot.acc_lim_theta * dt
    v_min, v_max = (speed, speed) if speed is not None else (params.min_vel_x, robot.max_vel_x)
    v_lo, v_hi = np.clip([v0 - dv, v0 + dv], v_min, v_max)
    w_lo, w_hi = np.clip([w0 - dw, w0 + dw], -robot.max_vel_theta, robot.max_vel_theta)
    return float(v_lo), float(v_hi), float(w_lo), float(w_hi)


def _samples(lo: float, hi: float, n: int) -> np.ndarray:
    """``n`` evenly spaced values over [lo, hi]; the one nearest 0 becomes exactly 0 when 0 lies
    inside, so driving straight and stopping are always among the samples (as in ROS's
    VelocityIterator, which adds 0)."""
    values = np.linspace(lo, hi, n) if n > 1 else np.array([(lo + hi) / 2])
    if lo <= 0.0 <= hi:
        values[np.argmin(np.abs(values))] = 0.0
    return values


def rollout(
    pose: tuple[float, float, float], v: np.ndarray, w: np.ndarray, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact unicycle poses for constant (v, w) at times ``t``: arrays (K, T) of x, y, θ.

    Uses the chord of the arc, v·t·sinc(ω t/2), in the direction θ0 + ω t/2, which is exact and
    has no singularity at ω = 0.
    """
    x0, y0, th0 = pose
    v, w, t = (np.asarray(a, dtype=float) for a in (v, w, t))
    wt = w[:, None] * t[None, :]
    chord = v[:, None] * t[None, :] * np.sinc(wt / (2 * np.pi))
    heading = th0 + wt / 2
    return x0 + chord * np.cos(heading), y0 + chord * np.sin(heading), th0 + wt


class _Polyline:
    """A path as segments with cumulative arc length and its sharp corners (vertices turning
    more than ``corner_angle``); consecutive duplicate points dropped."""

    def __init__(self, path: np.ndarray, corner_angle: float) -> None:
        keep = np.ones(len(path), dtype=bool)
        keep[1:] = np.any(np.abs(np.diff(path, axis=0)) > 1e-9, axis=1)
        pts = path[keep]
        if len(pts) == 1:
            pts = np.vstack([pts, pts])
        self.points = pts
        self.a, self.b = pts[:-1], pts[1:]
        self.ab = self.b - self.a
        self.length = np.hypot(self.ab[:, 0], self.ab[:, 1])
        self.cum = np.concatenate([[0.0], np.cumsum(self.length)])
        self.goal = pts[-1]
        heading = np.arctan2(self.ab[:, 1], self.ab[:, 0])
        turn = np.abs(np.angle(np.exp(1j * np.diff(heading))))
        self.corners = 1 + np.flatnonzero(turn > corner_angle)  # vertex indices

    def nearest(self, p: np.ndarray, segments: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """For points (P, 2): distance to the path (its first ``segments`` segments) and arc
        length of the nearest path point; ties go to the earlier segment."""
        a, ab, length = self.a[:segments], self.ab[:segments], self.length[:segments]
        ap = p[:, None, :] - a[None, :, :]
        l2 = length**2
        t = np.divide(
            np.einsum("psk,sk->ps", ap, ab), l2, out=np.zeros((len(p), len(l2))), where=l2 > 0
        )
        t = np.clip(t, 0.0, 1.0)
        d = ap - t[:, :, None] * ab[None, :, :]
        dist = np.hypot(d[:, :, 0], d[:, :, 1])
        seg = np.argmin(dist, axis=1)
        rows = np.arange(len(p))
        return dist[rows, seg], self.cum[seg] + t[rows, seg] * length[seg]

    def at(self, s: float) -> np.ndarray:
        """The path point at arc length ``s`` (clipped to the path)."""
        return np.array([np.interp(s, self.cum, self.points[:, k]) for k in range(2)])


def _check_inputs(
    pose: tuple[float, float, float],
    velocity: tuple[float, float],
    path: np.ndarray,
    obstacles: np.ndarray,
    robot_radius: float,
    dt: float,
) -> None:
    if len(pose) != 3 or not np.all(np.isfinite(pose)):
        raise ValueError(f"pose must be three finite numbers (x, y, theta), got {pose!r}")
    if len(velocity) != 2 or not np.all(np.isfinite(velocity)):
        raise ValueError(f"velocity must be two finite numbers (v, w), got {velocity!r}")
    if path.ndim != 2 or path.shape[1] != 2 or len(path) == 0 or not np.all(np.isfinite(path)):
        raise ValueError(f"path must be a finite (N, 2) array with N >= 1, got shape {path.shape}")
    if obstacles.ndim != 2 or obstacles.shape[1] != 2 or not np.all(np.isfinite(obstacles)):
        raise ValueError(f"obstacles must be a finite (M, 2) array, got shape {obstacles.shape}")
    if not robot_radius > 0 or not dt > 0:
        raise ValueError(f"robot_radius and dt must be > 0, got {robot_radius!r}, {dt!r}")


def dwa_control(
    pose: tuple[float, float, float],
    velocity: tuple[float, float],
    path: np.ndarray,
    obstacles: np.ndarray,
    params: DWAParams,
    robot: RobotSpec,
    dt: float,
    speed: float | None = None,
) -> DWAResult:
    """One DWA step: the best (v, ω) for the next control period ``dt``, for the disc ``robot``
    within its speed and acceleration limits.

    The stages, in order: sample velocities in the dynamic window and roll each out
    (:func:`_rollouts`; with ``speed``, a caller's braking profile, v is that one speed and
    only ω is sampled), check each rollout against the obstacles (:func:`_obstacle_terms`),
    find the local goal on the path (:func:`_local_goal`), score the admissible rollouts
    (:func:`_cost`) and take the cheapest (:func:`_choose`).

    ``admissible`` is True when some collision-free sample moves the robot forward (v > 0) and
    the best command is not to stand still short of the final goal (farther than
    ``sim_granularity``). A blocked robot ends in one of these two: no forward sample is free,
    or the ones that are free creep so close to the obstacle that the obstacle cost outweighs
    the progress left. Either way the command is a fallback, see :class:`DWAResult`.
    """
    path = np.asarray(path, dtype=float)
    obstacles = np.asarray(obstacles, dtype=float)
    if obstacles.size == 0:
        obstacles = obstacles.reshape(0, 2)
    _check_inputs(pose, velocity, path, obstacles, robot.radius, dt)
    rollouts = _rollouts(pose, velocity, params, robot, dt, speed)
    ok, occ = _obstacle_terms(rollouts, pose, obstacles, params, robot.radius)
    line = _Polyline(path, params.corner_angle)
    goal = _local_goal(line, pose, params)
    cost = _cost(rollouts, line, goal, ok, occ, params)
    return _choose(rollouts, cost, ok, line, pose, velocity, params)


@dataclass(frozen=True, eq=False)
class _Rollouts:
    """The sampled commands (v, w) (K,) and their rollouts: ``x``, ``y``, ``theta`` (K, T) at
    times ``t`` (T,), and ``body`` ((T − 1)·K, 2) the rollouts' points after the start, rollout
    by rollout. ``window`` is the dynamic window (v_lo, v_hi, w_lo, w_hi) they were drawn from."""

    v: np.ndarray
    w: np.ndarray
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    theta: np.ndarray
    body: np.ndarray
    window: tuple[float, float, float, float]


def _rollouts(
    pose: tuple[float, float, float],
    velocity: tuple[float, float],
    params: DWAParams,
    robot: RobotSpec,
    dt: float,
    speed: float | None,
) -> _Rollouts:
    """``vx_samples`` × ``vtheta_samples`` velocities spread over the dynamic window (see
    :func:`dynamic_window`), each held for ``sim_time`` (ROS ``use_dwa``) and rolled out at
    points at most ``sim_granularity`` apart at the top speed. With ``speed``, v is that one
    speed and only ω is sampled; the points are then at most ``sim_granularity`` apart at that
    speed."""
    window = dynamic_window(velocity, params, robot, dt, speed)
    v_lo, v_hi, w_lo, w_hi = window
    vx_samples, top = (1, speed) if speed is not None else (params.vx_samples, robot.max_vel_x)
    vv, ww = np.meshgrid(
        _samples(v_lo, v_hi, vx_samples), _samples(w_lo, w_hi, params.vtheta_samples), indexing="ij"
    )
    v, w = vv.ravel(), ww.ravel()
    steps = max(1, math.ceil(top * params.sim_time / params.sim_granularity - 1e-9))
    t = np.linspace(0.0, params.sim_time, steps + 1)
    xs, ys, ths = rollout(pose, v, w, t)
    body = np.column_stack([xs[:, 1:].ravel(), ys[:, 1:].ravel()])
    return _Rollouts(v, w, t, xs, ys, ths, body, window)


def _obstacle_terms(
    rollouts: _Rollouts,
    pose: tuple[float, float, float],
    obstacles: np.ndarray,
    params: DWAParams,
    robot_radius: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Per rollout: whether it is admissible, and its obstacle cost
    ``occdist_scale / max(min clearance − robot_radius, ε)``.

    A rollout is inadmissible if any of its points has clearance (distance from the robot
    centre to the nearest obstacle point) below ``robot_radius + safety_margin``. A robot that
    already is that close (lidar noise biases the nearest point low; a pushed robot) may also
    take trajectories that come at most ``MEDIAN_NOISE_M`` nearer than it starts (never under
    robot_radius) and end at least as far from obstacles as it starts, so it can slide out
    instead of freezing.
    """
    k = len(rollouts.v)
    if not len(obstacles):
        return np.ones(k, dtype=bool), np.zeros(k)
    threshold = robot_radius + params.safety_margin
    tree = cKDTree(obstacles)
    clearance = tree.query(rollouts.body)[0].reshape(k, len(rollouts.t) - 1)
    min_clear = clearance.min(axis=1)
    start_clear = float(tree.query(np.asarray(pose[:2], dtype=float))[0])
    ok = min_clear >= threshold
    if start_clear < threshold:
        floor = max(robot_radius, start_clear - MEDIAN_NOISE_M)
        ok |= (min_clear >= floor) & (clearance[:, -1] >= start_clear)
    return ok, params.occdist_scale / np.maximum(min_clear - robot_radius, _MIN_GAP)


@dataclass(frozen=True, eq=False)
class _LocalGoal:
    """The local goal g (``point``, at arc length ``s`` on the path), the arc length of the
    next ``stop``, the unit ``direction`` u from the robot toward g and the ``distance`` to g."""

    point: np.ndarray
    s: float
    stop: float
    direction: np.ndarray
    distance: float


def _local_goal(line: _Polyline, pose: tuple[float, float, float], params: DWAParams) -> _LocalGoal:
    """The path point ``goal_lookahead`` beyond the robot's projection onto the path, or the
    next stop when nearer: a sharp corner (see ``corner_angle``) more than ``sim_granularity``
    ahead, or the final goal. u is the robot's heading when it stands on g (ROS: the angle to
    the goal)."""
    robot_xy = np.asarray(pose[:2], dtype=float)
    # The robot is somewhere before the second sharp corner: on a boustrophedon path this keeps
    # it from projecting onto the neighbouring lane.
    reach = int(line.corners[1]) if len(line.corners) > 1 else None
    s_robot = float(line.nearest(robot_xy[None, :], reach)[1][0])
    ahead = line.cum[line.corners]
    ahead = ahead[ahead > s_robot + params.sim_granularity]
    stop = float(ahead[0]) if len(ahead) else float(line.cum[-1])
    s_goal = min(s_robot + params.goal_lookahead, stop)
    goal = line.at(s_goal)
    to_goal = goal - robot_xy
    dist = float(np.hypot(*to_goal))
    u = to_goal / dist if dist > 1e-9 else np.array([math.cos(pose[2]), math.sin(pose[2])])
    return _LocalGoal(goal, s_goal, stop, u, dist)


def _cost(
    rollouts: _Rollouts,
    line: _Polyline,
    goal: _LocalGoal,
    ok: np.ndarray,
    occ: np.ndarray,
    params: DWAParams,
) -> np.ndarray:
    """Each rollout's cost, inf for the inadmissible ones.

    Lower is better; ROS dwa_local_planner's four map-grid costs, in metres, plus the obstacle
    cost ``occ`` (see :func:`_obstacle_terms`). With e the rollout's end position,
    n = e + forward_point_distance·(cos θe, sin θe) its nose, g the local goal and u the unit
    vector from the robot toward it (see :func:`_local_goal`), and d_path the distance to the
    path up to g::

        cost = path_distance_bias/2 · (d_path(e) + a · d_path(n))        path + alignment
             + goal_distance_bias/2 · (|e − g| + |n − (g + f·u)|)         goal + goal front
             + occdist_scale / max(min clearance − robot_radius, ε)       obstacles

    with d_path(e) the mean over all the rollout's points, and
    a = 0 within ``forward_point_distance`` of a stop that is the local goal (as in ROS,
    keeping the nose on the path there destabilizes the stop) and 1 elsewhere. The nose terms
    make rotating in place toward a path behind the robot strictly better than standing still,
    so a robot facing away turns around (v = 0 samples are in the window whenever the robot is
    slow). Near a stop the end-point cost is least for the speed whose rollout ends on the goal,
    v ≈ d/sim_time, so the robot slows down smoothly (the acceleration needed is ≤ v/sim_time,
    within acc_lim_x whenever max_vel_x/sim_time is, as for the fleet's robot) and stops on the
    goal instead of overshooting.
    """
    k = len(rollouts.v)
    f = params.forward_point_distance
    end = np.column_stack([rollouts.x[:, -1], rollouts.y[:, -1]])
    heading = rollouts.theta[:, -1]
    nose = end + f * np.column_stack([np.cos(heading), np.sin(heading)])
    reach_goal = max(1, int(np.searchsorted(line.cum, goal.s)))
    body = rollouts.body
    d_body = line.nearest(np.vstack([body, nose]), reach_goal)[0]
    d_end = d_body[: len(body)].reshape(k, len(rollouts.t) - 1).mean(axis=1)
    d_nose = d_body[len(body) :]
    align = 0.0 if goal.s == goal.stop and goal.distance <= f else 1.0
    path_cost = d_end + align * d_nose
    g = goal.point
    goal_cost = np.hypot(*(end - g).T) + np.hypot(*(nose - (g + f * goal.direction)).T)
    cost = params.path_distance_bias / 2 * path_cost + params.goal_distance_bias / 2 * goal_cost
    return np.where(ok, cost + occ, np.inf)


def _choose(
    rollouts: _Rollouts,
    cost: np.ndarray,
    ok: np.ndarray,
    line: _Polyline,
    pose: tuple[float, float, float],
    velocity: tuple[float, float],
    params: DWAParams,
) -> DWAResult:
    """The cheapest rollout, and whether it is admissible (see :func:`dwa_control`); when no
    rollout is, braking (:func:`_brake`)."""
    k = int(np.argmin(cost))
    v, w = rollouts.v, rollouts.w
    standstill = v[k] == 0.0 and w[k] == 0.0
    robot_xy = np.asarray(pose[:2], dtype=float)
    arrived = np.hypot(*(line.goal - robot_xy)) <= params.sim_granularity
    admissible = bool(np.any(ok & (v > 0))) and not (standstill and not arrived)
    if np.isfinite(cost[k]):
        traj = np.column_stack([rollouts.x[k], rollouts.y[k], rollouts.theta[k]])
        return DWAResult(float(v[k]), float(w[k]), traj, float(cost[k]), admissible)
    v_lo, _, w_lo, w_hi = rollouts.window
    return _brake(pose, velocity, v_lo, w_lo, w_hi, rollouts.t)


def _brake(
    pose: tuple[float, float, float],
    velocity: tuple[float, float],
    v_lo: float,
    w_lo: float,
    w_hi: float,
    t: np.ndarray,
) -> DWAResult:
    """Fallback: slow down as hard as the window allows, keeping the current arc's curvature."""
    v0, w0 = velocity
    w = w0 * v_lo / v0 if v0 > 0 else 0.0
    w = float(np.clip(w, w_lo, w_hi))
    xs, ys, ths = rollout(pose, np.array([v_lo]), np.array([w]), t)
    traj = np.column_stack([xs[0], ys[0], ths[0]])
    return DWAResult(v_lo, w, traj, math.inf, False)
