"""The escape move out of a dead end, and a robot without work keeping clear of its peers.

A robot that makes no progress under DWA for ``agent.escape_after_s`` — boxed in, or caught in
a minimum of DWA's costs — turns in place onto the free direction nearest its path and drives a
short way straight along it (:func:`escape_heading`, :func:`start_escape`,
:func:`escape_step`). One that is stopped where a peer it gives way to is held up and cannot
get past its body instead moves out of that peer's way with the same kind of move
(:func:`in_their_way`, :func:`blocks_the_way`, :func:`way_out`, :func:`make_way`). A robot
without work stands still unless a peer's intent comes at it, and then steps aside, or it
blocks a held peer, and then moves out of its way the same way (:func:`keep_clear`).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy import ndimage

from agents.follow.primitives import gaps, held, kept_clear, rotate_in_place
from agents.follow.state import FollowParams, FollowState, Pose, Situation
from planners.dwa import DWAResult

ESCAPE_HEADINGS = 36
ESCAPE_MARGIN_M = 0.02
ESCAPE_HEADING_TOLERANCE = 0.05
# a robot this near the discs the peers it gives way to will cover is in their way (a peer
# cannot pass a body nearer its path than its own width and DWA's margins, as in a doorway),
# and making way ends this far (more: no dithering on the border) outside them
IN_THE_WAY_M = 0.12
WAY_MARGIN_M = 0.15
MAKE_WAY_MAX_M = 0.6
MAKE_WAY_STEP_M = 0.05
# metres of clearance a metre of the move must buy: a short step aside before a long retreat
WAY_COST_PER_M = 0.3
# scan points this far beyond a peer's body are the peer (its latest intent says where it stood)
PEER_BODY_MARGIN_M = 0.1
# how far round the robot, on what grid, it looks for a way for the peer past its body
WAY_WINDOW_M = 1.0
WAY_GRID_M = 0.04
WAY_SNAP_M = 0.1


def escape_heading(
    pose: Pose,
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
    free = kept_clear(walls, robots, now, margin) & (
        (along[:, -1] > gap_now) | (along[:, -1] >= margin)
    )
    if not free.any():
        return None
    if aim is None:
        return float(phi[free][np.argmax(along[free, -1])])
    return float(phi[free][np.argmin(off[free])])


def in_their_way(now: Situation, robot_radius: float) -> bool:
    """Whether the robot stands where a peer it gives way to cannot get past it: its body
    comes within ``IN_THE_WAY_M`` of the discs that a peer which says it is held up will cover
    (one of ``now.held``), and that peer cannot get round it (:func:`blocks_the_way`). A peer that
    drives on is not held: it passes by, or DWA takes it round the body. Where there is room,
    the peer's escape move or DWA takes it round too, and a move aside would only drive the
    brush over swept floor."""
    xy = np.asarray(now.pose[:2])
    tubes = [t for t in now.held if np.hypot(*(t - xy).T).min() < 2 * robot_radius + IN_THE_WAY_M]
    if not tubes:
        return False
    near = np.hypot(*(now.obstacles[:, None, :] - now.others[None, :, :]).transpose(2, 0, 1))
    walls = now.obstacles[~(near < robot_radius + PEER_BODY_MARGIN_M).any(axis=1)]
    return any(blocks_the_way(now.pose, walls, t, robot_radius) for t in tubes)


def blocks_the_way(pose: Pose, walls: np.ndarray, tube: np.ndarray, robot_radius: float) -> bool:
    """Whether a robot at ``pose`` stops a peer from getting along ``tube`` (the discs its
    intent will cover, in time order, the first where it stands): on a grid of
    ``WAY_GRID_M`` cells over the ``WAY_WINDOW_M`` round the robot, the cells a peer's centre
    can take (clear of the ``walls`` by a radius and the margin, of the robot by a diameter and
    the margin) hold no way from where the peer stands to the farthest disc of the tube on the
    grid. In a passage one robot wide they do not; in a room the peer goes round."""
    xy = np.asarray(pose[:2], dtype=float)
    n = round(2 * WAY_WINDOW_M / WAY_GRID_M)
    corner = xy - WAY_WINDOW_M
    occupied = np.zeros((n, n), dtype=bool)
    cells = np.floor((walls - corner) / WAY_GRID_M).astype(int)
    inside = ((cells >= 0) & (cells < n)).all(axis=1)
    occupied[cells[inside, 1], cells[inside, 0]] = True
    centres = corner + WAY_GRID_M * (np.indices((n, n))[::-1].transpose(1, 2, 0) + 0.5)
    clear = ndimage.distance_transform_edt(~occupied) * WAY_GRID_M
    free = (clear > robot_radius + ESCAPE_MARGIN_M) & (
        np.hypot(*(centres - xy).transpose(2, 0, 1)) > 2 * robot_radius + ESCAPE_MARGIN_M
    )
    at = np.floor((tube - corner) / WAY_GRID_M).astype(int)
    on = ((at >= 0) & (at < n)).all(axis=1)
    if not on[0] or on.sum() < 2:
        return False
    labels, _ = ndimage.label(free)
    start = _component_near(labels, at[0], round(WAY_SNAP_M / WAY_GRID_M))
    end = at[np.flatnonzero(on)[-1]]
    return start > 0 and labels[end[1], end[0]] != start


def _component_near(labels: np.ndarray, cell: np.ndarray, reach: int) -> int:
    """The label of the free cell nearest ``cell`` (col, row) within ``reach`` cells, 0 if none:
    a peer's own cell may read as too near a wall on a grid this coarse."""
    rows, cols = labels.shape
    r0, r1 = max(cell[1] - reach, 0), min(cell[1] + reach + 1, rows)
    c0, c1 = max(cell[0] - reach, 0), min(cell[0] + reach + 1, cols)
    window = labels[r0:r1, c0:c1]
    if not window.any():
        return 0
    rr, cc = np.nonzero(window)
    k = np.argmin(np.hypot(rr + r0 - cell[1], cc + c0 - cell[0]))
    return int(window[rr[k], cc[k]])


def way_out(
    pose: Pose, obstacles: np.ndarray, peers: np.ndarray, robot_radius: float
) -> tuple[float, float] | None:
    """(direction, distance) of the straight move, at most ``MAKE_WAY_MAX_M``, that best takes a
    robot standing in its peers' way out of it, or None when none does.

    A move is worth the clearance its end keeps from the discs the ``peers`` will cover (counted
    up to ``WAY_MARGIN_M`` beyond the body) less ``WAY_COST_PER_M`` for each metre of it, so a
    short step aside beats a long retreat that ends a little clearer; no point of it may come
    nearer the obstacles than min(robot_radius + ``ESCAPE_MARGIN_M``, the gap now), nor nearer
    those discs than min(robot_radius, the gap now) (as :func:`escape_step` keeps it), and its
    end must be out of the way (``IN_THE_WAY_M``). In a passage one robot wide that is back out of
    it, the way the peer is heading.

    This is the push of Push and Swap (Luna and Bekris 2011): the robot in the way of one of
    higher priority moves to a place off that robot's path, instead of standing on it while the
    other cannot pass its body. The peer's body itself is in the scan, so no move goes through
    it."""
    xy = np.asarray(pose[:2], dtype=float)
    phi = np.linspace(-math.pi, math.pi, ESCAPE_HEADINGS, endpoint=False)
    steps = np.arange(MAKE_WAY_STEP_M, MAKE_WAY_MAX_M + 1e-9, MAKE_WAY_STEP_M)
    dirs = np.column_stack([np.cos(phi), np.sin(phi)])
    points = xy[None, None, :] + steps[None, :, None] * dirs[:, None, :]
    walls, robots = (
        g.reshape(len(phi), len(steps))
        for g in gaps(points.reshape(-1, 2), obstacles, peers, robot_radius)
    )
    wall_now, robot_now = (g[0] for g in gaps(xy[None, :], obstacles, peers, robot_radius))
    clear = (
        np.minimum.accumulate(walls, axis=1) >= min(robot_radius + ESCAPE_MARGIN_M, wall_now)
    ) & (np.minimum.accumulate(robots, axis=1) >= min(robot_radius, robot_now))
    value = np.where(clear, np.minimum(robots, robot_radius + WAY_MARGIN_M), -np.inf)
    value = value - WAY_COST_PER_M * steps[None, :]
    if not np.isfinite(value).any():
        return None
    best_h, best_d = np.unravel_index(np.argmax(value), value.shape)
    if robots[best_h, best_d] < robot_radius + IN_THE_WAY_M:
        return None
    return float(phi[best_h]), float(steps[best_d])


def make_way(state: FollowState, now: Situation, params: FollowParams) -> FollowState:
    """Begin the move out of the peers' way (:func:`way_out`), forward or in reverse, whichever
    needs the smaller turn first; where there is none, the escape move to the side that ends
    clearest (:func:`start_escape` without an aim)."""
    move = way_out(now.pose, now.obstacles, now.peers, params.robot.radius)
    if move is None:
        return start_escape(state, now, None, params)
    return _begin(state, now.pose, *move, making_way=True)


def start_escape(
    state: FollowState, now: Situation, aim: np.ndarray | None, params: FollowParams
) -> FollowState:
    """Begin the escape move toward ``aim`` (or to the clearest side, see
    :func:`escape_heading`), driving forward or in reverse, whichever needs the smaller turn
    first; the state is unchanged when no direction is free."""
    distance = params.agent.escape_distance
    travel = escape_heading(now.pose, aim, now.obstacles, now.peers, params.robot.radius, distance)
    if travel is None:
        return state
    return _begin(state, now.pose, travel, distance, making_way=False)


def _begin(
    state: FollowState, pose: Pose, travel: float, distance: float, making_way: bool
) -> FollowState:
    """A straight move of ``distance`` in the direction ``travel``, driven forward or in
    reverse, whichever needs the smaller turn from ``pose`` first."""
    forward = abs(math.remainder(travel - pose[2], 2 * math.pi)) <= math.pi / 2
    return replace(
        state,
        blocked_s=0.0,
        escape_m=distance,
        escape_heading=travel if forward else math.remainder(travel + math.pi, 2 * math.pi),
        escape_sign=1 if forward else -1,
        making_way=making_way,
    )


def escape_step(
    state: FollowState, now: Situation, params: FollowParams
) -> tuple[FollowState, DWAResult] | None:
    """One step of the escape move: turn in place onto ``state.escape_heading``, then drive
    straight (in reverse when ``escape_sign`` is −1) at ``escape_speed`` while ``escape_m`` is
    left and the way is clear — no point of it nearer the obstacles, or the peers (judged apart),
    than the robot radius or than the robot is now; None when the move is over or its way has
    closed."""
    pose, robot, dt = now.pose, params.robot, params.dt
    error = math.remainder(state.escape_heading - pose[2], 2 * math.pi)
    if abs(error) > ESCAPE_HEADING_TOLERANCE:
        return state, held(pose, *rotate_in_place(error, now.velocity, robot, dt), params.dwa)
    sign = state.escape_sign
    way = sign * np.array([math.cos(pose[2]), math.sin(pose[2])])
    ahead = np.asarray(pose[:2]) + np.linspace(0.02, state.escape_m, 5)[:, None] * way
    walls, robots = gaps(
        np.vstack([np.asarray(pose[:2])[None, :], ahead]), now.obstacles, now.peers, robot.radius
    )
    if not kept_clear(walls[1:], robots[1:], (walls[0], robots[0]), robot.radius):
        return None
    v0 = now.velocity[0]
    speed = params.agent.escape_speed
    v = min(max(sign * speed, v0 - robot.acc_lim_x * dt), v0 + robot.acc_lim_x * dt)
    result = held(pose, v, 0.0, params.dwa)
    left = state.escape_m - abs(v) * dt if v * sign > 0 else state.escape_m
    return replace(state, escape_m=max(0.0, left)), result


def keep_clear(
    state: FollowState, now: Situation, params: FollowParams
) -> tuple[FollowState, DWAResult]:
    """The step of a robot without work: stand still, unless it is in the way of a peer held up
    (:func:`in_their_way`) — then move out of it (:func:`make_way`) — or a peer's intent
    (``now.peers``) comes within ``ESCAPE_MARGIN_M`` of its body — then step aside with the
    escape move, to the side that ends clearest. A robot that has finished its path would
    otherwise stand on someone else's."""
    robot, dt = params.robot, params.dt
    if state.escape_m <= 0 and in_their_way(now, robot.radius):
        state = make_way(state, now, params)
    elif state.escape_m <= 0 and len(now.peers):
        d = np.hypot(*(now.peers - np.asarray(now.pose[:2])).T)
        if d.min() < 2 * robot.radius + ESCAPE_MARGIN_M:
            state = start_escape(state, now, None, params)
    if state.escape_m > 0:
        stepped = escape_step(state, now, params)
        if stepped is not None:
            return stepped
        state = replace(state, escape_m=0.0)
    v0, w0 = now.velocity
    v = max(0.0, v0 - robot.acc_lim_x * dt)
    w = min(max(0.0, w0 - robot.acc_lim_theta * dt), w0 + robot.acc_lim_theta * dt)
    return state, held(now.pose, v, w, params.dwa)
