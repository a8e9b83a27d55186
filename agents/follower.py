"""Following a waypoint path with DWA: the agent's pure control step.

The agent keeps an index of the next waypoint; a waypoint counts as reached when the robot is
level with it along the segment into it, near that segment (see :func:`advance`). DWA is given
the local path from the previous waypoint on, a few metres long, so its path-distance cost
keeps the robot on the lane, not merely near the next point. On the approach to a sharp corner
the speed follows the braking profile of :func:`stop_speed`.

DWA scores where a rollout goes, not the way a robot turns onto a lane: a robot that faces far
off its next segment takes an arc that bulges a quarter metre off the path — on a coverage path
that sweeps the neighbouring lane instead of its own. So, as move_base's planners rotate in
place toward the path first, a robot whose heading is more than ``align_enter`` off the
direction to its next waypoint stops and turns in place (time-optimal under the angular
acceleration limit) until it is within ``align_exit``, and only then drives.

Where the segment it is on runs beside a wall at about the wall follower's distance (see
:func:`wall_beside`), the robot is steered by the wall follower on its scan instead
(:mod:`planners.wall_follow`): the edge pass of a robot vacuum. DWA's obstacle cost keeps a
robot a few centimetres farther from a wall than its lane, and its pose estimate is centimetres
off, so the band along walls went unswept; held to the wall it sees, the brush reaches it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from agents.peers import rim_points
from fleet.params import AgentParams, FleetConfig
from planners.dwa import DWAParams, DWAResult, dwa_control, rollout
from planners.polyline import densify
from planners.robot import RobotSpec
from planners.wall_follow import WallFollowParams, to_robot_frame, wall_follow_step

LOCAL_PATH_M = 3.0
PROGRESS_M = 0.02
TURN_PROGRESS_RAD = 0.05
MEDIAN_BEAMS = 5
ESCAPE_HEADINGS = 36
ESCAPE_MARGIN_M = 0.02
ESCAPE_HEADING_TOLERANCE = 0.05
# wall_beside judges the wall along a segment in bins this long, and over at least this many
EDGE_BIN_M = 0.05
EDGE_MIN_BINS = 3
# the wall follower's command held this long (s) must keep this much (m) beyond the radius
EDGE_CHECK_S = 0.5
EDGE_MARGIN_M = 0.005


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

    @property
    def done(self) -> bool:
        return self.index >= len(self.waypoints)


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


def advance(state: FollowState, xy: np.ndarray, agent: AgentParams) -> FollowState:
    """Skip the waypoints the robot at ``xy`` has reached: it is at most ``along_tolerance``
    short of (or past) the waypoint along the segment into it and at most
    ``waypoint_tolerance`` beside that segment, or within ``along_tolerance`` of it
    (``goal_tolerance`` for the last one). Lanes thus end where they end, whatever the robot's
    small sideways offset, instead of being cut short by a radius around their ends."""
    wps, i = state.waypoints, state.index
    n = len(wps)
    while i < n:
        near = agent.goal_tolerance if i == n - 1 else agent.along_tolerance
        if math.dist(xy, wps[i]) <= near:
            i += 1
            continue
        if i > 0:
            seg = wps[i] - wps[i - 1]
            length = float(np.hypot(*seg))
            if length > 1e-9:
                rel = xy - wps[i - 1]
                along = float(rel @ seg) / length
                beside = abs(float(rel[0] * seg[1] - rel[1] * seg[0])) / length
                if along >= length - agent.along_tolerance and beside <= agent.waypoint_tolerance:
                    i += 1
                    continue
        break
    if i == state.index:
        return state
    return FollowState(wps, i, skipped=state.skipped, missed=state.missed)


def _ahead(start: np.ndarray, waypoints: np.ndarray, horizon_m: float) -> np.ndarray:
    """``start`` and the ``waypoints`` after it up to the first at least ``horizon_m`` along."""
    pts = [start]
    length = 0.0
    for waypoint in waypoints:
        length += math.dist(pts[-1], waypoint)
        pts.append(waypoint)
        if length >= horizon_m:
            break
    return np.array(pts, dtype=float)


def local_path(state: FollowState, xy: np.ndarray, horizon_m: float = LOCAL_PATH_M) -> np.ndarray:
    """The path ahead: the segment the robot is on and the waypoints up to ``horizon_m``."""
    wps, i = state.waypoints, state.index
    return _ahead(wps[i - 1] if i > 0 else xy, wps[i:], horizon_m)


def predict(
    pose: tuple[float, float, float], velocity: tuple[float, float], dt: float
) -> tuple[float, float, float]:
    """The pose after ``dt`` at ``velocity``. A command computed from a scan takes effect a
    latency later; planning it from the pose predicted for that moment (a Smith predictor)
    keeps the robot from weaving about its lane when the latency is a whole control period."""
    if dt <= 0:
        return pose
    xs, ys, ths = rollout(pose, np.array([velocity[0]]), np.array([velocity[1]]), np.array([dt]))
    return float(xs[0, 0]), float(ys[0, 0]), float(ths[0, 0])


def scan_points(
    pose: tuple[float, float, float],
    ranges: np.ndarray,
    angle_min: float,
    angle_increment: float,
) -> np.ndarray:
    """World-frame obstacle points of a scan; each range is a 5-beam median to damp noise."""
    r = np.asarray(ranges, dtype=float)
    half = MEDIAN_BEAMS // 2
    padded = np.concatenate([r[-half:], r, r[:half]])
    windows = np.lib.stride_tricks.sliding_window_view(padded, MEDIAN_BEAMS)
    r = np.median(windows, axis=1)
    ok = np.isfinite(r)
    a = pose[2] + angle_min + angle_increment * np.nonzero(ok)[0]
    return np.column_stack([pose[0] + r[ok] * np.cos(a), pose[1] + r[ok] * np.sin(a)])


def peer_in_the_way(
    state: FollowState, xy: np.ndarray, peers: np.ndarray, robot_radius: float, reach: float
) -> bool:
    """Whether a peer will cover (``peers``: the centres of its intent's discs) a spot within
    two robot radii and ``ESCAPE_MARGIN_M`` of the robot or of its path over the next ``reach``
    metres: a robot that makes no progress then waits for the peer, it is not stuck."""
    if not len(peers):
        return False
    ahead = densify(_ahead(xy, state.waypoints[state.index :], reach), robot_radius / 4)
    along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(ahead, axis=0).T))])
    ahead = ahead[along <= reach]
    _, robots = gaps(ahead, np.zeros((0, 2)), np.asarray(peers), robot_radius)
    return bool(robots.min() < robot_radius + ESCAPE_MARGIN_M)


def carrot(state: FollowState, xy: np.ndarray, lookahead: float) -> np.ndarray:
    """The point ``lookahead`` metres beyond the robot's projection onto the segment into the
    next waypoint, clipped to that waypoint (pure pursuit's carrot): aiming there merges the
    robot back onto the lane instead of cutting across to the lane's end."""
    target = state.waypoints[state.index]
    if state.index == 0:
        return target
    start = state.waypoints[state.index - 1]
    seg = target - start
    length = float(np.hypot(*seg))
    if length < 1e-9:
        return target
    along = float((xy - start) @ seg) / length
    return start + seg * min(1.0, max(0.0, along + lookahead) / length)


def stop_speed(
    state: FollowState,
    xy: np.ndarray,
    params: DWAParams,
    robot: RobotSpec,
    along_tolerance: float,
) -> float | None:
    """The speed for the approach to a stop, or None when the next waypoint is no stop or is
    farther than the braking distance from full speed.

    A stop is the last waypoint or one where the path turns by more than ``corner_angle``. The
    speed is the largest from which the robot can still brake to rest on it,
    v = √(2·acc_lim_x·d) with d the distance left along the segment (Fox et al. 1997's
    admissible velocity, applied to the stop as to an obstacle). DWA alone would aim its
    rollouts' end points at the stop and approach it at v ≈ d/sim_time, ever more slowly.
    """
    wps, i = state.waypoints, state.index
    if 0 < i < len(wps) - 1:
        a, b = wps[i] - wps[i - 1], wps[i + 1] - wps[i]
        turn = abs(math.remainder(math.atan2(b[1], b[0]) - math.atan2(a[1], a[0]), 2 * math.pi))
        if turn <= params.corner_angle:
            return None
    start = wps[i - 1] if i > 0 else xy
    seg = wps[i] - start
    length = float(np.hypot(*seg))
    left = math.dist(xy, wps[i]) if length < 1e-9 else length - float((xy - start) @ seg) / length
    braking = robot.max_vel_x**2 / (2 * robot.acc_lim_x)
    if left > braking + along_tolerance:
        return None
    return math.sqrt(2 * robot.acc_lim_x * max(left - along_tolerance / 2, 0.0))


def rotate_in_place(
    heading_error: float, velocity: tuple[float, float], robot: RobotSpec, dt: float
) -> tuple[float, float]:
    """(v, ω) that brakes to a stop and turns by ``heading_error``: the turn rate is the
    largest from which the robot can still stop on the heading, √(2·acc_lim_theta·|error|),
    capped at max_vel_theta and reached within the acceleration limits."""
    v0, w0 = velocity
    v = max(0.0, v0 - robot.acc_lim_x * dt)
    rate = min(robot.max_vel_theta, math.sqrt(2.0 * robot.acc_lim_theta * abs(heading_error)))
    dw = robot.acc_lim_theta * dt
    w = min(max(math.copysign(rate, heading_error), w0 - dw), w0 + dw)
    return v, w


def _held(pose: tuple[float, float, float], v: float, w: float, params: DWAParams) -> DWAResult:
    """A command chosen outside DWA, with its trajectory over ``sim_time`` for the intent."""
    xs, ys, ths = rollout(pose, np.array([v]), np.array([w]), np.linspace(0, params.sim_time, 11))
    return DWAResult(v, w, np.column_stack([xs[0], ys[0], ths[0]]), 0.0, True)


def gaps(
    points: np.ndarray, obstacles: np.ndarray, peers: np.ndarray, robot_radius: float
) -> tuple[np.ndarray, np.ndarray]:
    """Clearance of a robot centred at each of ``points`` (P, 2), from the obstacle points and,
    apart, from the discs of other robots centred at ``peers`` (to their rims): two (P,)
    arrays, inf where there is nothing of that kind."""
    walls = np.full(len(points), np.inf)
    robots = np.full(len(points), np.inf)
    if len(obstacles):
        walls = cKDTree(obstacles).query(points)[0]
    if len(peers):
        robots = cKDTree(peers).query(points)[0] - robot_radius
    return walls, robots


def _kept_clear(
    walls: np.ndarray, robots: np.ndarray, now: tuple[np.ndarray, np.ndarray], margin: float
) -> np.ndarray:
    """Whether each row of clearances (see :func:`gaps`) stays at least min(``margin``, the
    clearance now) from the walls and, judged apart, from the peers: a peer's disc that
    overlaps the robot must not license a move into a wall."""
    return (walls.min(axis=-1) >= np.minimum(margin, now[0])) & (
        robots.min(axis=-1) >= np.minimum(margin, now[1])
    )


def escape_heading(
    pose: tuple[float, float, float],
    aim: np.ndarray | None,
    obstacles: np.ndarray,
    peers: np.ndarray,
    robot_radius: float,
    distance: float,
) -> float | None:
    """The direction of travel of the escape move, or None when no straight move is free.

    Of ``ESCAPE_HEADINGS`` directions, the free ones are those along which a straight move of
    ``distance`` keeps every point at least min(robot_radius + ESCAPE_MARGIN_M, the gap now)
    clear of the obstacles and, judged apart, of the peers (see :func:`gaps`), and ends farther
    out than the robot is now (or clear of that margin); the one closest to the direction of
    ``aim`` wins, or without an aim the one that ends clearest. A disc robot can always turn in
    place, so any free direction can be taken: this is Nav2's Spin-then-DriveOnHeading recovery
    with the heading chosen from the scan instead of fixed, and it frees a robot from the
    pockets where DWA's forward arcs are all blocked and the way straight back is too."""
    xy = np.asarray(pose[:2], dtype=float)
    phi = np.linspace(-math.pi, math.pi, ESCAPE_HEADINGS, endpoint=False)
    if aim is not None:
        toward = math.atan2(aim[1] - xy[1], aim[0] - xy[0])
        off = np.abs(np.remainder(phi - toward + math.pi, 2 * math.pi) - math.pi)
    if len(obstacles) == 0 and len(peers) == 0:
        return float(phi[np.argmin(off)]) if aim is not None else None
    now = gaps(xy[None, :], obstacles, peers, robot_radius)
    gap_now = float(min(now[0][0], now[1][0]))
    steps = np.linspace(0.02, distance, 6)
    dirs = np.column_stack([np.cos(phi), np.sin(phi)])
    points = xy[None, None, :] + steps[None, :, None] * dirs[:, None, :]
    walls, robots = (
        g.reshape(len(phi), len(steps))
        for g in gaps(points.reshape(-1, 2), obstacles, peers, robot_radius)
    )
    along = np.minimum(walls, robots)
    margin = robot_radius + ESCAPE_MARGIN_M
    free = _kept_clear(walls, robots, now, margin) & (
        (along[:, -1] > gap_now) | (along[:, -1] >= margin)
    )
    if not free.any():
        return None
    if aim is None:
        return float(phi[free][np.argmax(along[free, -1])])
    return float(phi[free][np.argmin(off[free])])


def start_escape(
    state: FollowState,
    pose: tuple[float, float, float],
    aim: np.ndarray | None,
    obstacles: np.ndarray,
    peers: np.ndarray,
    robot_radius: float,
    agent: AgentParams,
) -> FollowState:
    """Begin the escape move toward ``aim`` (or to the clearest side, see
    :func:`escape_heading`), driving forward or in reverse, whichever needs the smaller turn
    first; the state is unchanged when no direction is free."""
    travel = escape_heading(pose, aim, obstacles, peers, robot_radius, agent.escape_distance)
    if travel is None:
        return state
    forward = abs(math.remainder(travel - pose[2], 2 * math.pi)) <= math.pi / 2
    return replace(
        state,
        blocked_s=0.0,
        escape_m=agent.escape_distance,
        escape_heading=travel if forward else math.remainder(travel + math.pi, 2 * math.pi),
        escape_sign=1 if forward else -1,
    )


def escape_step(
    state: FollowState,
    pose: tuple[float, float, float],
    velocity: tuple[float, float],
    obstacles: np.ndarray,
    peers: np.ndarray,
    params: DWAParams,
    robot: RobotSpec,
    dt: float,
    agent: AgentParams,
) -> tuple[FollowState, DWAResult] | None:
    """One step of the escape move: turn in place onto ``state.escape_heading``, then drive
    straight (in reverse when ``escape_sign`` is −1) at ``escape_speed`` while ``escape_m`` is
    left and the way is clear — no point of it nearer the obstacles, or the peers (judged apart),
    than the robot radius or than the robot is now; None when the move is over or its way has
    closed."""
    error = math.remainder(state.escape_heading - pose[2], 2 * math.pi)
    if abs(error) > ESCAPE_HEADING_TOLERANCE:
        return state, _held(pose, *rotate_in_place(error, velocity, robot, dt), params)
    sign = state.escape_sign
    way = sign * np.array([math.cos(pose[2]), math.sin(pose[2])])
    ahead = np.asarray(pose[:2]) + np.linspace(0.02, state.escape_m, 5)[:, None] * way
    walls, robots = gaps(
        np.vstack([np.asarray(pose[:2])[None, :], ahead]), obstacles, peers, robot.radius
    )
    if not _kept_clear(walls[1:], robots[1:], (walls[0], robots[0]), robot.radius):
        return None
    v0 = velocity[0]
    v = min(max(sign * agent.escape_speed, v0 - robot.acc_lim_x * dt), v0 + robot.acc_lim_x * dt)
    result = _held(pose, v, 0.0, params)
    left = state.escape_m - abs(v) * dt if v * sign > 0 else state.escape_m
    return replace(state, escape_m=max(0.0, left)), result


def keep_clear(
    state: FollowState,
    pose: tuple[float, float, float],
    velocity: tuple[float, float],
    obstacles: np.ndarray,
    peers: np.ndarray,
    params: DWAParams,
    robot: RobotSpec,
    dt: float,
    agent: AgentParams,
) -> tuple[FollowState, DWAResult]:
    """The step of a robot without work: stand still, unless a peer's intent (``peers``, the
    centres of the discs it will cover, see :func:`agents.peers.intent_centres`) comes within
    ``ESCAPE_MARGIN_M`` of its body — then step aside with the escape move, to the side that
    ends clearest. A robot that has finished its path would otherwise stand on someone else's.
    """
    xy = np.asarray(pose[:2], dtype=float)
    if state.escape_m <= 0 and len(peers):
        d = np.hypot(*(peers - xy).T)
        if d.min() < 2 * robot.radius + ESCAPE_MARGIN_M:
            state = start_escape(state, pose, None, obstacles, peers, robot.radius, agent)
    if state.escape_m > 0:
        stepped = escape_step(state, pose, velocity, obstacles, peers, params, robot, dt, agent)
        if stepped is not None:
            return stepped
        state = replace(state, escape_m=0.0)
    v0, w0 = velocity
    v = max(0.0, v0 - robot.acc_lim_x * dt)
    w = min(max(0.0, w0 - robot.acc_lim_theta * dt), w0 + robot.acc_lim_theta * dt)
    return state, _held(pose, v, w, params)


def wall_beside(
    state: FollowState,
    pose: tuple[float, float, float],
    obstacles: np.ndarray,
    wall: WallFollowParams,
    agent: AgentParams,
) -> int:
    """The side of the segment the robot is on (+1 left, −1 right) that runs along a wall at
    about the wall follower's distance, or 0.

    Beside the segment's stretch from ``edge_window`` behind the robot to ``edge_window`` ahead
    (up to its end), the scan's ``obstacles`` must line the segment at a lateral distance of
    at most ``wall.distance + edge_slack`` in at least ``edge_cover`` of its 5 cm bins (a
    wall the plan's lane hugs, not a door or the lane beyond an outside corner), and the robot
    must be on its way along the segment: heading within ``edge_heading`` of it and at most
    ``waypoint_tolerance`` beside it (DWA's obstacle cost may have pushed it a decimetre off a
    lane by a wall; the wall follower brings it back). Of two such sides (a corridor) the
    nearer wall is taken."""
    wps, i = state.waypoints, state.index
    if i == 0 or state.done:
        return 0
    start, seg = wps[i - 1], wps[i] - wps[i - 1]
    length = float(np.hypot(*seg))
    if length < 1e-9 or len(obstacles) == 0:
        return 0
    u = seg / length
    n = np.array([-u[1], u[0]])
    xy = np.asarray(pose[:2], dtype=float)
    along_robot = float((xy - start) @ u)
    heading_off = abs(math.remainder(pose[2] - math.atan2(u[1], u[0]), 2 * math.pi))
    if heading_off > agent.edge_heading or abs(float((xy - start) @ n)) > agent.waypoint_tolerance:
        return 0
    lo = max(0.0, along_robot - agent.edge_window)
    hi = min(length, along_robot + agent.edge_window)
    bins = int((hi - lo) / EDGE_BIN_M)
    if bins < EDGE_MIN_BINS:
        return 0
    rel = np.asarray(obstacles) - start
    along, beside = rel @ u, rel @ n
    near = (along >= lo) & (along < lo + bins * EDGE_BIN_M)
    best, best_gap = 0, math.inf
    for side in (1, -1):
        lateral = side * beside
        on = near & (lateral > 0) & (lateral <= wall.distance + agent.edge_slack)
        cover = np.unique(((along[on] - lo) / EDGE_BIN_M).astype(int)).size / bins
        if cover >= agent.edge_cover and (gap := float(np.median(lateral[on]))) < best_gap:
            best, best_gap = side, gap
    return best


def edge_step(
    state: FollowState,
    pose: tuple[float, float, float],
    velocity: tuple[float, float],
    obstacles: np.ndarray,
    peers: np.ndarray,
    wall: WallFollowParams,
    params: DWAParams,
    robot: RobotSpec,
    dt: float,
    agent: AgentParams,
    max_speed: float | None,
) -> tuple[int, DWAResult | None]:
    """(side, command) of the wall follower on the segment the robot is on, capped at
    ``max_speed``; (0, None) where no wall runs beside it (:func:`wall_beside`), where a peer is
    within ``edge_peer_clear``, where the follower finds no wall on its scan, or where its
    command held for ``EDGE_CHECK_S`` would bring the robot nearer an obstacle than
    ``EDGE_MARGIN_M`` beyond its radius (or than it is now): DWA, which checks its rollouts,
    then drives (the wall follower turns a robot that meets its lane at an angle only within its
    angular acceleration, a few centimetres closer to the wall first)."""
    xy = np.asarray(pose[:2], dtype=float)
    if len(peers) and float(np.hypot(*(peers - xy).T).min()) < agent.edge_peer_clear:
        return 0, None
    side = wall_beside(state, pose, obstacles, wall, agent)
    if not side:
        return 0, None
    points = to_robot_frame(obstacles, pose)
    command = wall_follow_step(points, side, velocity, wall, robot, dt, max_speed)
    if command is None:
        return 0, None
    xs, ys, _ = rollout(
        pose, np.array([command.v]), np.array([command.w]), np.linspace(0.0, EDGE_CHECK_S, 6)
    )
    clear, _ = gaps(np.column_stack([xs[0], ys[0]]), obstacles, np.zeros((0, 2)), robot.radius)
    if clear[1:].min() < min(robot.radius + EDGE_MARGIN_M, clear[0]):
        return 0, None
    return side, _held(pose, command.v, command.w, params)


def control_step(
    state: FollowState,
    pose: tuple[float, float, float],
    velocity: tuple[float, float],
    obstacles: np.ndarray,
    params: DWAParams,
    robot: RobotSpec,
    dt: float,
    agent: AgentParams,
    peers: np.ndarray | None = None,
    wall: WallFollowParams | None = None,
) -> tuple[FollowState, DWAResult | None]:
    """Advance along the path and choose a command; ``None`` when the path is finished.

    ``obstacles`` are points (the scan); ``peers`` the centres of the discs that other robots
    will cover (:func:`agents.peers.intent_centres`), which DWA sees as their rims.

    A waypoint the robot has come no closer to (by ``PROGRESS_M``) for ``give_up_after_s`` is
    skipped, so a robot whose way is shut, that is caught in a local minimum of the DWA costs,
    or whose pose estimate has drifted into a wall moves on instead of waiting forever; the
    skipped spot stays uncleaned and shows in the coverage. Turning in place toward the path
    holds the watchdog's clock (only coming closer resets it, so a robot that turns, drives off
    and turns back again is still given up on), and so does the escape move, which starts after
    ``escape_after_s`` without progress under DWA — boxed in, or caught in a minimum of its
    costs (see :func:`escape_heading`). Time without progress while a peer is in the way
    (:func:`peer_in_the_way` within DWA's reach, max_vel_x·sim_time) does not count, up to
    ``give_way_max_s`` of it in a row: a robot that gives way to one crossing its path waits
    for it instead of giving up the lane it was about to sweep.

    With ``wall`` (the wall follower's parameters), a segment that runs along a wall
    (:func:`wall_beside`) is driven by the wall follower on the scan, braking into the
    segment's end as DWA would, while no peer is within ``edge_peer_clear``: near peers, DWA
    and its give-way keep the robots apart.
    """
    xy = np.array(pose[:2])
    state = advance(state, xy, agent)
    if state.done:
        return state, None
    if state.edge_side:
        state = replace(state, edge_side=0)
    peers = np.zeros((0, 2)) if peers is None else peers
    seen = np.vstack([obstacles, rim_points(peers, robot.radius)]) if len(peers) else obstacles
    if state.escape_m > 0:
        escaping = escape_step(state, pose, velocity, obstacles, peers, params, robot, dt, agent)
        if escaping is not None:
            return escaping
        state = replace(state, escape_m=0.0)
    target = state.waypoints[state.index]
    dist = math.dist(xy, target)
    aim = carrot(state, xy, agent.align_lookahead)
    error = math.remainder(math.atan2(aim[1] - xy[1], aim[0] - xy[0]) - pose[2], 2 * math.pi)
    limit = agent.align_exit if state.aligning else agent.align_enter
    if abs(error) > limit and dist > agent.waypoint_tolerance:
        result = _held(pose, *rotate_in_place(error, velocity, robot, dt), params)
        if not state.aligning:
            state = replace(state, aligning=True, best_error=math.inf)
        progressed = abs(error) < state.best_error - TURN_PROGRESS_RAD
    else:
        state = replace(state, aligning=False)
        path = local_path(state, xy)
        result = None
        speed = stop_speed(state, xy, params, robot, agent.along_tolerance)
        if wall is not None:
            side, result = edge_step(
                state,
                pose,
                velocity,
                obstacles,
                peers,
                wall,
                params,
                robot,
                dt,
                agent,
                speed,
            )
            state = replace(state, edge_side=side)
        if result is None and speed is not None:
            v_now = velocity[0]
            speed = min(max(speed, v_now - robot.acc_lim_x * dt), v_now + robot.acc_lim_x * dt)
            result = dwa_control(pose, velocity, path, seen, params, robot, dt, speed)
            if not (result.admissible and math.isfinite(result.cost)):
                result = None
        if result is None:
            result = dwa_control(pose, velocity, path, seen, params, robot, dt)
        progressed = dist < state.best_dist - PROGRESS_M
        blocked = 0.0 if progressed else state.blocked_s + dt
        state = replace(state, blocked_s=blocked)
        if blocked >= agent.escape_after_s:
            state = start_escape(state, pose, aim, obstacles, peers, robot.radius, agent)
    if progressed and state.aligning:
        return replace(state, best_error=abs(error)), result
    if progressed:
        return replace(state, stalled_s=0.0, yielded_s=0.0, best_dist=dist), result
    if state.yielded_s + dt <= agent.give_way_max_s and peer_in_the_way(
        state, xy, peers, robot.radius, robot.max_vel_x * params.sim_time
    ):
        return replace(state, yielded_s=state.yielded_s + dt), result
    if state.stalled_s + dt >= agent.give_up_after_s:
        short = state.best_dist > agent.swept_within
        missed = (*state.missed, state.index) if short else state.missed
        gave_up = FollowState(
            state.waypoints, state.index + 1, skipped=state.skipped + 1, missed=missed
        )
        return gave_up, result
    return replace(state, stalled_s=state.stalled_s + dt), result
