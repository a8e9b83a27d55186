"""Following a waypoint path with DWA: the follower's step.

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

Where the segment it is on runs beside a wall, the wall follower drives instead
(:mod:`agents.follow.edge`); a robot that makes no progress escapes
(:mod:`agents.follow.escape`) and in the end gives the waypoint up (:func:`follow_step`).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from agents.follow.edge import edge_step
from agents.follow.escape import ESCAPE_MARGIN_M, escape_step, start_escape
from agents.follow.primitives import gaps, held, rotate_in_place
from agents.follow.state import FollowParams, FollowState, Pose, Situation
from agents.follow.track import reached, track_step
from agents.peers import rim_points
from fleet.params import AgentParams
from planners.dwa import DWAResult, dwa_control, rollout
from planners.polyline import densify
from planners.tracking import Frenet

LOCAL_PATH_M = 3.0
PROGRESS_M = 0.02
TURN_PROGRESS_RAD = 0.05


def advance(
    state: FollowState, xy: np.ndarray, agent: AgentParams, stop_tolerance: float | None = None
) -> FollowState:
    """Skip the waypoints the robot at ``xy`` has reached: it is at most ``along_tolerance``
    short of (or past) the waypoint along the segment into it and at most
    ``waypoint_tolerance`` beside that segment, or within ``along_tolerance`` of it
    (``goal_tolerance`` for the last one). Lanes thus end where they end, whatever the robot's
    small sideways offset, instead of being cut short by a radius around their ends. On a
    tracked segment (:attr:`FollowState.tracked`) a waypoint is reached level with it on the
    simplified segment the tracker drives, a stop within ``stop_tolerance`` (the tracker's;
    ``along_tolerance`` when not given) short of it (:func:`agents.follow.track.reached`), so
    the robot turns onto the next lane on its line."""
    wps, i = state.waypoints, state.index
    n = len(wps)
    stop_tolerance = agent.along_tolerance if stop_tolerance is None else stop_tolerance
    while i < n:
        if state.track_from is not None and state.profile is not None and state.track_from < i:
            if reached(state.at(i), xy, stop_tolerance, agent.waypoint_tolerance):
                i += 1
                continue
            break
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
    return state.at(i)


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


def predict(pose: Pose, velocity: tuple[float, float], dt: float) -> Pose:
    """The pose after ``dt`` at ``velocity``. A command computed from a scan takes effect a
    latency later; planning it from the pose predicted for that moment (a Smith predictor)
    keeps the robot from weaving about its lane when the latency is a whole control period."""
    if dt <= 0:
        return pose
    xs, ys, ths = rollout(pose, np.array([velocity[0]]), np.array([velocity[1]]), np.array([dt]))
    return float(xs[0, 0]), float(ys[0, 0]), float(ths[0, 0])


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


def stop_speed(state: FollowState, xy: np.ndarray, params: FollowParams) -> float | None:
    """The speed for the approach to a stop, or None when the next waypoint is no stop or is
    farther than the braking distance from full speed.

    A stop is the last waypoint, one where the path turns by more than ``corner_angle``, or
    ``state.stop_at`` (the robot must wait there before driving on). The
    speed is the largest from which the robot can still brake to rest on it,
    v = √(2·acc_lim_x·d) with d the distance left along the segment (Fox et al. 1997's
    admissible velocity, applied to the stop as to an obstacle). DWA alone would aim its
    rollouts' end points at the stop and approach it at v ≈ d/sim_time, ever more slowly.
    """
    robot, along_tolerance = params.robot, params.agent.along_tolerance
    wps, i = state.waypoints, state.index
    if 0 < i < len(wps) - 1 and i != state.stop_at:
        a, b = wps[i] - wps[i - 1], wps[i + 1] - wps[i]
        turn = abs(math.remainder(math.atan2(b[1], b[0]) - math.atan2(a[1], a[0]), 2 * math.pi))
        if turn <= params.dwa.corner_angle:
            return None
    start = wps[i - 1] if i > 0 else xy
    seg = wps[i] - start
    length = float(np.hypot(*seg))
    left = math.dist(xy, wps[i]) if length < 1e-9 else length - float((xy - start) @ seg) / length
    braking = robot.max_vel_x**2 / (2 * robot.acc_lim_x)
    if left > braking + along_tolerance:
        return None
    return math.sqrt(2 * robot.acc_lim_x * max(left - along_tolerance / 2, 0.0))


def drive(
    state: FollowState, now: Situation, params: FollowParams
) -> tuple[FollowState, DWAResult]:
    """The command along the segment: the wall follower's where it runs beside a wall
    (:func:`agents.follow.edge.edge_step`), else DWA's (Fox, Burgard, Thrun 1997) on the local
    path, with the peers' discs as their rims, braking into a stop at :func:`stop_speed` while
    that is admissible."""
    robot, dt = params.robot, params.dt
    xy = np.array(now.pose[:2])
    peers = now.peers
    seen = (
        np.vstack([now.obstacles, rim_points(peers, robot.radius)]) if len(peers) else now.obstacles
    )
    path = local_path(state, xy)
    speed = stop_speed(state, xy, params)
    side, result = edge_step(state, now, params, speed)
    state = replace(state, edge_side=side)
    if result is None and speed is not None:
        v_now = now.velocity[0]
        speed = min(max(speed, v_now - robot.acc_lim_x * dt), v_now + robot.acc_lim_x * dt)
        result = dwa_control(now.pose, now.velocity, path, seen, params.dwa, robot, dt, speed)
        if not (result.admissible and math.isfinite(result.cost)):
            result = None
    if result is None:
        result = dwa_control(now.pose, now.velocity, path, seen, params.dwa, robot, dt)
    return state, result


def follow_step(
    state: FollowState, now: Situation, params: FollowParams
) -> tuple[FollowState, DWAResult | None]:
    """Advance along the path and choose a command; ``None`` when the path is finished.

    In order: an escape move under way goes on (:mod:`agents.follow.escape`); a robot facing
    more than ``align_enter`` off its lane turns in place onto it; else it drives
    (:func:`drive`: the edge pass or DWA). Without progress, the watchdog
    (:func:`watchdog`) counts toward giving the waypoint up, and after ``escape_after_s``
    under DWA the escape move begins (boxed in, or caught in a minimum of its costs, see
    :func:`agents.follow.escape.escape_heading`). Turning in place toward the path holds the
    watchdog's clock (only coming closer resets it, so a robot that turns, drives off and turns
    back again is still given up on), and so does the escape move.
    """
    agent = params.agent
    xy = np.array(now.pose[:2])
    state = advance(state, xy, agent, params.tracker.stop_tolerance)
    if state.done:
        return state, None
    if state.edge_side:
        state = replace(state, edge_side=0)
    if state.escape_m > 0:
        escaping = escape_step(state, now, params)
        if escaping is not None:
            return escaping
        state = replace(state, escape_m=0.0)
    dist = math.dist(xy, state.waypoints[state.index])
    if state.tracked and (tracking := track_step(state, now, params)) is not None:
        return _progress(*tracking, dist, now, params)
    aim = carrot(state, xy, agent.align_lookahead)
    error = math.remainder(math.atan2(aim[1] - xy[1], aim[0] - xy[0]) - now.pose[2], 2 * math.pi)
    limit = agent.align_exit if state.aligning else agent.align_enter
    if abs(error) > limit and dist > agent.waypoint_tolerance:
        turn = rotate_in_place(error, now.velocity, params.robot, params.dt)
        result = held(now.pose, *turn, params.dwa)
        if not state.aligning:
            state = replace(state, aligning=True, best_error=math.inf)
        if abs(error) < state.best_error - TURN_PROGRESS_RAD:
            return replace(state, best_error=abs(error)), result
    else:
        state, result = drive(replace(state, aligning=False), now, params)
        progressed = dist < state.best_dist - PROGRESS_M
        blocked = 0.0 if progressed else state.blocked_s + params.dt
        state = replace(state, blocked_s=blocked)
        if blocked >= agent.escape_after_s:
            state = start_escape(state, now, aim, params)
        if progressed:
            return replace(state, stalled_s=0.0, yielded_s=0.0, best_dist=dist), result
    return watchdog(state, now, params), result


def _progress(
    state: FollowState, result: DWAResult, dist: float, now: Situation, params: FollowParams
) -> tuple[FollowState, DWAResult]:
    """The watchdog's bookkeeping after a tracker's step: turning in place holds its clock, as
    it does for the follower's own turns; driving nearer the next waypoint resets it."""
    if state.aligning:
        error = abs(
            Frenet.of(now.pose, *state.waypoints[state.index - 1 : state.index + 1]).heading
        )
        if error < state.best_error - TURN_PROGRESS_RAD:
            return replace(state, best_error=error), result
        return watchdog(state, now, params), result
    if dist < state.best_dist - PROGRESS_M:
        return replace(state, stalled_s=0.0, yielded_s=0.0, blocked_s=0.0, best_dist=dist), result
    return watchdog(state, now, params), result


def watchdog(state: FollowState, now: Situation, params: FollowParams) -> FollowState:
    """A step without progress toward the next waypoint.

    A waypoint the robot has come no closer to (by ``PROGRESS_M``) for ``give_up_after_s`` is
    skipped, so a robot whose way is shut, that is caught in a local minimum of the DWA costs,
    or whose pose estimate has drifted into a wall moves on instead of waiting forever; the
    skipped spot stays uncleaned and shows in the coverage, and one given up farther than the
    brush reaches (half ``cleaning_width``) from it is remembered in ``missed`` (its piece is
    unswept). Time without
    progress while a peer is in the way (:func:`peer_in_the_way` within DWA's reach,
    max_vel_x·sim_time) does not count, up to ``give_way_max_s`` of it in a row: a robot that
    gives way to one crossing its path waits for it instead of giving up the lane it was about
    to sweep."""
    agent, robot, dt = params.agent, params.robot, params.dt
    xy = np.array(now.pose[:2])
    reach = robot.max_vel_x * params.dwa.sim_time
    if state.yielded_s + dt <= agent.give_way_max_s and peer_in_the_way(
        state, xy, now.peers, robot.radius, reach
    ):
        return replace(state, yielded_s=state.yielded_s + dt)
    if state.stalled_s + dt >= agent.give_up_after_s:
        short = state.best_dist > robot.cleaning_width / 2
        missed = (*state.missed, state.index) if short else state.missed
        return state.at(state.index + 1, skipped=state.skipped + 1, missed=missed)
    return replace(state, stalled_s=state.stalled_s + dt)
