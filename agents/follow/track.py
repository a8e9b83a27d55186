"""The path tracker: the plan's sweeps driven by a tracking law, DWA's check on every command.

On the segments of the plan's sweeps (:attr:`FollowState.tracked`) the robot drives as the plan
prices it (:mod:`planners.tracking`): at rest on each stop, it turns in place onto the next
segment's heading; along the segment, Samson's law steers it onto the line at the speed of the
braking profile into the next stop. Each driving command is checked as DWA checks a velocity
(Fox et al. 1997): the arc it brakes along from that command must keep the body clear of the
scan's points and, apart, of the peers' discs (:func:`clear`). A command that fails, or a robot
too far off its segment to track (pushed aside, or back from a detour), is left to DWA
(:func:`agents.follow.motion.drive`), and tracking takes over again once the robot is back on
its line and the way is clear.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from agents.follow.primitives import gaps, held
from agents.follow.state import FollowParams, FollowState, Pose, Situation
from planners.dwa import MEDIAN_NOISE_M, DWAResult, rollout
from planners.polyline import densify
from planners.tracking import (
    Frenet,
    Profile,
    braking_arc,
    samson_turn_rate,
    track_speed,
    turn_rate,
)

# a scan point this far (m) inside the body on the plan's path ahead is the scan's noise at a
# wall the plan keeps coordinator.wall_clearance from, not something on the path
PATH_NOISE_M = 0.01
# the braking arc is checked at points this far apart (m)
CHECK_SPACING_M = 0.02


def tracked(waypoints: np.ndarray, sweep_from: int, params: FollowParams) -> FollowState:
    """A follower whose segments after waypoint ``sweep_from`` (the plan's sweeps) are tracked,
    by their :class:`planners.tracking.Profile`."""
    profile = Profile.of(
        waypoints,
        sweep_from,
        params.stop_angle,
        params.simplify_tolerance,
        params.tracker,
        params.robot,
    )
    return FollowState(waypoints, track_from=sweep_from, profile=profile)


def segment(state: FollowState) -> tuple[int, np.ndarray, np.ndarray]:
    """The simplified segment k the robot is on, heading for waypoint ``state.index``, and its
    two ends."""
    assert state.profile is not None
    profile, wps = state.profile, state.waypoints
    k = int(profile.segment[state.index])
    return k, wps[profile.kept[k - 1]], wps[profile.kept[k]]


def reached(state: FollowState, xy: np.ndarray, stop_tolerance: float, beside_max: float) -> bool:
    """Whether the robot at ``xy`` has reached waypoint ``state.index`` of a tracked segment:
    its projection on the simplified segment is level with the waypoint's (within
    ``stop_tolerance`` short of it where the robot comes to rest there) and it is at most
    ``beside_max`` beside the segment."""
    assert state.profile is not None
    _, a, b = segment(state)
    i = state.index
    here = Frenet.of((float(xy[0]), float(xy[1]), 0.0), a, b)
    there = Frenet.of((*state.waypoints[i], 0.0), a, b)
    stop = state.profile.is_stop(i) or i == state.stop_at
    return (
        here.along >= there.along - (stop_tolerance if stop else 0.0)
        and abs(here.left) <= beside_max
    )


def reference(state: FollowState, pose: Pose) -> tuple[Frenet, tuple[tuple[float, float], ...]]:
    """The robot against its reference: the simplified segment it is on, or the arc that
    rounds one of its ends when the robot is abreast of that arc; with the speed limits ahead
    as (distance, speed) pairs: the arc it is on (0 m ahead), the next arc's start or the
    segment's end (0 m/s at a stop), and the order of passage's ``stop_at`` on the segment."""
    assert state.profile is not None
    profile, wps = state.profile, state.waypoints
    k, a, b = segment(state)
    error = Frenet.of(pose, a, b)
    short = error.length - error.along
    limits: list[tuple[float, float]] = []
    if state.index <= state.stop_at <= profile.kept[k]:
        held = Frenet.of((*wps[state.stop_at], 0.0), a, b)
        limits.append((max(held.along - error.along, 0.0), 0.0))
    into = profile.tangent(wps, k)
    out_of = profile.tangent(wps, k - 1)
    v_end = float(profile.speeds[k])
    if into and short <= into:
        c = wps[profile.kept[k + 1]]
        return error.on_arc(pose, a, b, c, profile.radii[k]), ((0.0, v_end), *limits)
    limits.append((max(short - into, 0.0), v_end))
    if out_of and error.along <= out_of:
        before = wps[profile.kept[k - 2]]
        arc = error.on_arc(pose, before, a, b, profile.radii[k - 1])
        return arc, ((0.0, float(profile.speeds[k - 1])), *limits)
    return error, tuple(limits)


def _along(points: list[np.ndarray], ends: list[np.ndarray], length: float) -> np.ndarray:
    """``points`` (the start) run on through ``ends`` for ``length`` metres, densified."""
    left = length
    for end in ends:
        step = math.dist(points[-1], end)
        if step >= left:
            points.append(points[-1] + (end - points[-1]) * (left / max(step, 1e-12)))
            break
        points.append(end)
        left -= step
    return densify(np.array(points), CHECK_SPACING_M)


def path_ahead(state: FollowState, pose: Pose, length: float) -> tuple[np.ndarray, np.ndarray]:
    """Points at most ``CHECK_SPACING_M`` apart of the path ahead of the robot's projection
    onto it, ``length`` metres along it or up to its next stop (beyond a stop the robot turns
    first, and checks again): the simplified path the tracker drives, and the plan's own."""
    assert state.profile is not None
    profile, wps, i = state.profile, state.waypoints, state.index
    k, a, b = segment(state)
    error = Frenet.of(pose, a, b)
    u = (b - a) / max(error.length, 1e-12)
    last = k
    while last < len(profile.kept) - 1 and profile.speeds[last] > 0.0:
        last += 1
    last_wp = int(profile.kept[last])
    if i <= state.stop_at < last_wp:
        last_wp = state.stop_at
        last = int(profile.segment[last_wp])
    ends = [wps[j] for j in profile.kept[k : last + 1] if j <= last_wp]
    tracked_path = _along([a + u * min(max(error.along, 0.0), error.length)], ends, length)
    raw = Frenet.of(pose, wps[i - 1], wps[i])
    ru = (wps[i] - wps[i - 1]) / max(raw.length, 1e-12)
    start = wps[i - 1] + ru * min(max(raw.along, 0.0), raw.length)
    return tracked_path, _along([start], list(wps[i : last_wp + 1]), length)


def clear(
    now: Situation,
    v: float,
    w: float,
    ahead: tuple[np.ndarray, np.ndarray],
    params: FollowParams,
) -> bool:
    """Whether (v, ω) keeps the body ``tracker.check_margin`` clear of the scan's points along
    the path ``ahead`` (:func:`path_ahead`: something the plan does not know stands on it, a
    peer or a box) and as clear as along the plan's own path there (the simplification cut no
    corner of a table), along the arc the robot brakes along from the command, and of the
    peers' discs along DWA's own rollout
    (the command held for ``dwa.sim_time``, as far ahead as the peers' intents are judged);
    where the robot is nearer already, it may come no more than ``MEDIAN_NOISE_M`` nearer, and
    never nearer than ``MEDIAN_NOISE_M`` (step by step that allowance let a robot 1.2 cm off its
    line creep onto a table's edge)."""
    radius, margin = params.robot.radius, params.tracker.check_margin
    tracked_path, plan = ahead
    if len(tracked_path) and len(now.obstacles):
        walls, _ = gaps(tracked_path, now.obstacles, np.zeros((0, 2)), radius)
        planned, _ = gaps(plan, now.obstacles, np.zeros((0, 2)), radius)
        if (
            walls.min() - radius < margin - PATH_NOISE_M
            or walls.min() < planned.min() - MEDIAN_NOISE_M
        ):
            return False
    here = np.asarray(now.pose[:2], dtype=float)[None, :]
    arc = braking_arc(
        now.pose, v, w, now.velocity[0], params.dt, params.robot.acc_lim_x, CHECK_SPACING_M
    )
    if len(arc) and len(now.obstacles):
        walls, _ = gaps(np.vstack([here, arc]), now.obstacles, np.zeros((0, 2)), radius)
        walls = walls - radius
        if walls[1:].min() < max(MEDIAN_NOISE_M, min(margin, walls[0] - MEDIAN_NOISE_M)):
            return False
    if not len(now.peers) or v <= 0:
        return True
    steps = max(2, math.ceil(v * params.dwa.sim_time / CHECK_SPACING_M) + 1)
    xs, ys, _ = rollout(
        now.pose, np.array([v]), np.array([w]), np.linspace(0, params.dwa.sim_time, steps)
    )
    _, robots = gaps(np.column_stack([xs[0], ys[0]]), np.zeros((0, 2)), now.peers, radius)
    robots = robots - radius
    return bool(
        robots[1:].min() >= min(margin + params.dwa.safety_margin, robots[0] - MEDIAN_NOISE_M)
    )


def track_step(
    state: FollowState, now: Situation, params: FollowParams
) -> tuple[FollowState, DWAResult] | None:
    """The tracker's command on a tracked segment, or None where DWA drives: a peer's intent
    comes within ``agent.edge_peer_clear`` (near peers DWA and its give-way drive, as for the
    edge pass: a peer that gives way moves, and the check below judges only where it is), the
    robot is more than ``rejoin_distance`` off its reference or heads more than
    ``rejoin_heading`` off it (away from a stop it turns at), or the command fails
    :func:`clear` (the path checked as far as the robot needs to stop, and ``clear_ahead``
    farther).

    At the segment's start, after a stop, a robot heading more than ``turn_heading`` off the
    segment brakes to rest and turns in place onto it, to within ``heading_tolerance``
    (``aligning``); otherwise it drives by Samson's law at the braking profile's speed."""
    assert state.profile is not None
    tracker, robot, dt = params.tracker, params.robot, params.dt
    if (
        len(now.everyone)
        and float(np.hypot(*(now.everyone - np.asarray(now.pose[:2])).T).min())
        < params.agent.edge_peer_clear
    ):
        return None
    error, limits = reference(state, now.pose)
    if abs(error.left) > tracker.rejoin_distance:
        return None
    k, start = int(state.profile.segment[state.index]), state.index - 1
    after_stop = state.profile.speeds[k - 1] == 0.0 or start == state.stop_at
    limit = tracker.heading_tolerance if state.aligning else tracker.turn_heading
    if after_stop and error.along < tracker.rejoin_distance and abs(error.heading) > limit:
        v0, w0 = now.velocity
        if v0 > tracker.creep_speed:
            v, w = 0.0, 0.0
        else:
            dw = robot.acc_lim_theta * dt
            v, w = 0.0, min(max(turn_rate(-error.heading, w0, dt, robot), w0 - dw), w0 + dw)
        return replace(state, aligning=True), held(now.pose, v, w, params.dwa)
    if abs(error.heading) > tracker.rejoin_heading:
        return None
    v = min(
        track_speed(short, error.heading, v_end, now.velocity[0], dt, tracker, robot)
        for short, v_end in limits
    )
    v0, w0 = now.velocity
    dv, dw = robot.acc_lim_x * dt, robot.acc_lim_theta * dt
    v = min(max(v, v0 - dv, 0.0), v0 + dv)
    w = samson_turn_rate(v, error, tracker)
    w = min(max(w, -robot.max_vel_theta, w0 - dw), robot.max_vel_theta, w0 + dw)
    reach = (v0 + v) / 2 * dt + v * v / (2 * robot.acc_lim_x) + tracker.clear_ahead
    if not clear(now, v, w, path_ahead(state, now.pose, reach), params):
        return None
    return replace(state, aligning=False), held(now.pose, v, w, params.dwa)
