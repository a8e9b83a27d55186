"""Giving way: a robot that stands where a peer it gives way to is about to drive leaves the
peer's way, stepping aside or backing along its own path, and waits there.

DWA with the peers' discs as obstacles keeps a robot from driving *into* a peer's way; it does
nothing for a robot already in it. Two robots at work that meet where there is no room to pass
(a strip between furniture and a wall, adjacent lanes that end in one corner) then hold each
other: the one with the right of way sees the other in its scan and cannot get by, the other
sees its own path ahead covered and escapes toward it, back into the first. So, as in
prioritized planning (Erdmann and Lozano-Pérez 1987) the lower-ranked robot plans round the
higher-ranked one's trajectory, the robot that gives way (:func:`agents.peers.gives_way`)
treats the discs of the other's intent that come within ``GIVE_WAY_GAP_M`` of its body as the
other's and leaves its way (:func:`give_way`): it steps aside to the nearest spot that keeps
that gap from all of the other's discs, straight across free floor by the scan
(:func:`side_spot`, driven as the escape move drives), where there is room beside the way; else
it backs off (:func:`back_off`) in reverse along the path it came by, which the plan laid clear
of the map and which it has just driven, while that takes it farther from the discs and the
scan shows the way behind free. It stops where the discs keep the gap, and the follower's
give-way waiting (``agent.give_way_max_s``) holds it there until the peer has passed; the watchdog
measures its progress afresh from where it waits, and a robot that backed past a waypoint of
its path heads for that waypoint again. Where neither is possible (no room beside,
the path's start behind), the follower goes on as before (DWA, the escape move).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from agents.follow.escape import escape_step
from agents.follow.primitives import gaps, held, rotate_in_place
from agents.follow.state import FollowParams, FollowState, Situation
from planners.dwa import DWAResult
from planners.polyline import densify

# a peer's disc nearer the robot's body than this (m) puts it in the peer's way
GIVE_WAY_GAP_M = 0.03
# a spot to step aside to is looked for in this many directions, this far away (m), and must
# keep this much more (m) than GIVE_WAY_GAP_M from every disc of the peers
SIDE_HEADINGS = 24
SIDE_STEPS_M = (0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5)
SIDE_SPARE_M = 0.01
# the point the robot backs toward lies this far (m) back along its path
BACK_LOOKAHEAD_M = 0.25
# reversing speed (m/s) and the heading error (rad) beyond which it turns in place first
BACK_SPEED = 0.2
BACK_ALIGN_RAD = 0.6
# turn-rate gain (1/s) on the reversing heading error
BACK_GAIN = 2.0
# the way behind is checked at points this far apart (m), to keep this much of the clearance
# the robot has now (m) from the scan's points, and never less than the lidar's noise
CHECK_SPACING_M = 0.02
NOISE_M = 0.005


def behind(state: FollowState, xy: np.ndarray, length: float) -> np.ndarray:
    """The robot's path back from the foot of ``xy`` on the segment into waypoint
    ``state.index``, through the waypoints before it, ``length`` metres long (or to the path's
    start): points (K, 2), the first the foot; one point when there is no way back."""
    wps, i = state.waypoints, min(state.index, len(state.waypoints) - 1)
    if i == 0:
        return xy[None, :]
    a, b = wps[i - 1], wps[i]
    seg = b - a
    n = float(seg @ seg)
    t = 0.0 if n < 1e-12 else min(1.0, max(0.0, float((xy - a) @ seg) / n))
    back = np.vstack([a + t * seg, wps[i - 1 :: -1]])
    steps = np.hypot(*np.diff(back, axis=0).T)
    keep = np.concatenate([[True], steps > 1e-9])
    back, along = back[keep], np.concatenate([[0.0], np.cumsum(steps[keep[1:]])])
    if along[-1] <= length:
        return back
    k = int(np.searchsorted(along, length))
    end = back[k - 1] + (back[k] - back[k - 1]) * (length - along[k - 1]) / (
        along[k] - along[k - 1]
    )
    return np.vstack([back[:k], end])


def in_the_way(now: Situation, params: FollowParams) -> np.ndarray:
    """The centres of the discs of the intents the robot gives way to (``now.peers``) that come
    within ``GIVE_WAY_GAP_M`` of its body."""
    if not len(now.peers):
        return now.peers
    d = np.hypot(*(now.peers - np.asarray(now.pose[:2])).T)
    return now.peers[d < 2 * params.robot.radius + GIVE_WAY_GAP_M]


def side_spot(now: Situation, params: FollowParams) -> tuple[float, float] | None:
    """The nearest spot (of ``SIDE_HEADINGS`` directions × ``SIDE_STEPS_M``) at least
    ``GIVE_WAY_GAP_M`` + ``SIDE_SPARE_M`` clear of the body of every disc of ``now.peers``,
    reached along a straight line that keeps ``dwa.safety_margin`` from the scan's points (or
    what the robot keeps now, if less), the clearest of the nearest: its (direction, distance),
    or None."""
    robot = params.robot
    xy = np.asarray(now.pose[:2], dtype=float)
    phi = np.linspace(-math.pi, math.pi, SIDE_HEADINGS, endpoint=False)
    units = np.column_stack([np.cos(phi), np.sin(phi)])
    need = 2 * robot.radius + GIVE_WAY_GAP_M + SIDE_SPARE_M
    wall_now = gaps(xy[None, :], now.obstacles, np.zeros((0, 2)), robot.radius)[0][0]
    keep = max(NOISE_M, min(robot.radius + params.dwa.safety_margin, wall_now))
    for step in SIDE_STEPS_M:
        spots = xy + step * units
        clear = np.hypot(*(spots[:, None, :] - now.peers[None, :, :]).transpose(2, 0, 1))
        ok = clear.min(axis=1) >= need
        if not ok.any():
            continue
        along = np.linspace(CHECK_SPACING_M, step, max(2, int(step / CHECK_SPACING_M)))
        line = xy + along[None, :, None] * units[ok][:, None, :]
        walls, _ = gaps(line.reshape(-1, 2), now.obstacles, np.zeros((0, 2)), robot.radius)
        free = walls.reshape(len(line), len(along)).min(axis=1) >= keep
        if free.any():
            best = int(np.argmax(clear.min(axis=1)[ok][free]))
            return float(phi[ok][free][best]), step
    return None


def come_back(state: FollowState, now: Situation, params: FollowParams) -> FollowState:
    """A robot that has given way (``yielded_s`` > 0) and stands behind the waypoint it came by,
    farther than ``agent.along_tolerance`` from it, heads for that waypoint again: it drives
    its path back from there once the peer has passed, instead of cutting across to the
    segment ahead round whatever stood beside it (the pieces it reported swept stay swept)."""
    wps, i = state.waypoints, state.index
    if state.yielded_s <= 0 or not 1 < i < len(wps):
        return state
    xy = np.asarray(now.pose[:2], dtype=float)
    if (xy - wps[i - 1]) @ (wps[i] - wps[i - 1]) >= 0:
        return state
    if math.dist(xy, wps[i - 1]) <= params.agent.along_tolerance:
        return state
    return replace(state.at(i - 1), yielded_s=state.yielded_s)


def give_way(
    state: FollowState, now: Situation, params: FollowParams
) -> tuple[FollowState, DWAResult] | None:
    """One step of leaving the way of a peer it gives way to (see the module's docstring): an
    escape move begun to the spot beside (:func:`side_spot`), or a step of backing off
    (:func:`back_off`); None when the robot is in no peer's way, or can do neither."""
    state = come_back(state, now, params)
    if state.yielded_s >= params.agent.give_way_max_s or not len(in_the_way(now, params)):
        return None
    spot = side_spot(now, params)
    if spot is None:
        return back_off(state, now, params)
    travel, distance = spot
    forward = abs(math.remainder(travel - now.pose[2], 2 * math.pi)) <= math.pi / 2
    aside = replace(
        state,
        blocked_s=0.0,
        aligning=False,
        stalled_s=0.0,
        best_dist=math.inf,
        escape_m=distance,
        escape_heading=travel if forward else math.remainder(travel + math.pi, 2 * math.pi),
        escape_sign=1 if forward else -1,
    )
    aside = replace(aside, yielded_s=state.yielded_s + params.dt)
    return escape_step(aside, now, params) or back_off(state, now, params)


def back_off(
    state: FollowState, now: Situation, params: FollowParams
) -> tuple[FollowState, DWAResult] | None:
    """One step of backing out of a peer's way (see the module's docstring), or None when the
    robot is in no peer's way, or backing would not take it farther from the peer's discs or
    runs into the scan's points: the follower then goes on as without it. The step counts as
    time given way, so the watchdog does not count it toward giving the waypoint up."""
    robot, dt = params.robot, params.dt
    discs = in_the_way(now, params)
    if not len(discs):
        return None
    xy = np.asarray(now.pose[:2], dtype=float)
    way = behind(state, xy, BACK_LOOKAHEAD_M)
    if len(way) < 2:
        return None
    target = way[-1]
    nearest = lambda p: float(np.hypot(*(discs - p).T).min())  # noqa: E731
    if nearest(target) <= nearest(xy):
        return None
    line = densify(np.vstack([xy, target]), CHECK_SPACING_M)
    walls, _ = gaps(line, now.obstacles, np.zeros((0, 2)), robot.radius)
    if walls[1:].min() < max(NOISE_M, min(params.dwa.safety_margin + robot.radius, walls[0])):
        return None
    travel = math.atan2(target[1] - xy[1], target[0] - xy[0])
    error = math.remainder(travel - (now.pose[2] + math.pi), 2 * math.pi)
    state = replace(
        state,
        yielded_s=state.yielded_s + dt,
        blocked_s=0.0,
        aligning=False,
        stalled_s=0.0,
        best_dist=math.inf,
    )
    if abs(error) > BACK_ALIGN_RAD:
        return state, held(now.pose, *rotate_in_place(error, now.velocity, robot, dt), params.dwa)
    v0 = now.velocity[0]
    v = max(-BACK_SPEED, v0 - robot.acc_lim_x * dt)
    w0 = now.velocity[1]
    w = min(max(BACK_GAIN * error, -robot.max_vel_theta), robot.max_vel_theta)
    w = min(max(w, w0 - robot.acc_lim_theta * dt), w0 + robot.acc_lim_theta * dt)
    return state, held(now.pose, v, w, params.dwa)
