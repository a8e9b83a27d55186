"""Everything about the other robots: their intents, how an agent gives way to them, how far
they are along their plans, and where they are for SLAM.

Every agent publishes its intent (:func:`own_intent`) over the next ``intent_horizon_s``: the
path ahead at cruising speed while it follows one (:func:`path_intent`), else where its current
command takes it (:func:`intent_points`). Robots are ranked by id (:func:`gives_way`);
an agent treats the intents of the robots ranked above it as obstacles for the time they cover
(:func:`intent_centres`, which DWA sees as :func:`rim_points`), so DWA keeps it out of their
way, stops it short of a crossing, or — through the follower's escape move — makes it step
aside when one of them comes at it. The robot with the right of way sees the other only in its
scan. A fixed priority order is the simplest rule under which two robots never both yield to
each other (prioritized planning, Erdmann and Lozano-Pérez 1987, applied to the robots'
short-term trajectories). A robot without work gives way to everyone.

The intents also say where the peers are (:func:`peer_discs`), which the agent cuts out of the
scan it gives SLAM (:func:`cut_out`, :func:`without_peers`): a robot that drives past one
standing still is a moving wall to its scan matcher, which then slides the standing robot's pose
along with it. And they say how far each peer is along its plan (:func:`progress`), which
the order of passage waits on (:mod:`agents.passage`).
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace

import numpy as np

from agents.follow.state import FollowState
from fleet.protocol import Intent, LaserScan
from planners.dwa import rollout
from planners.robot import RobotSpec

# A centre kept r + m from N points on a peer's rim of radius r can come within
# r·cos(π/N) + √((r + m)² − r²·sin²(π/N)) of the peer's centre between two of them: with 12
# points and dwa.safety_margin 0.01 m that is 1.3 mm short of 2r (bodies overlapping), with
# 24 it keeps 7 mm clear.
RIM_POINTS = 24
PEER_MASK_MARGIN_M = 0.05
# an intent announces at most this many waypoints of the path ahead
INTENT_WAYPOINTS = 30


@dataclass(frozen=True)
class PeerProgress:
    """What a peer's latest intent said: its plan, the waypoint it heads for, when."""

    plan_id: int
    waypoint: int
    stamp: float


def progress(intents: Mapping[str, Intent]) -> dict[str, PeerProgress]:
    """How far each peer is along its plan, by its latest intent."""
    return {rid: PeerProgress(i.plan_id, i.waypoint, i.stamp) for rid, i in intents.items()}


def intent_points(
    pose: tuple[float, float, float], v: float, w: float, stamp: float, horizon_s: float
) -> np.ndarray:
    """Rows (t, x, y): the robot's positions at 11 times over ``horizon_s`` if it holds (v, ω)."""
    t = np.linspace(0.0, horizon_s, 11)
    xs, ys, _ = rollout(pose, np.array([v]), np.array([w]), t)
    return np.column_stack([stamp + t, xs[0], ys[0]])


def path_intent(
    xy: np.ndarray, ahead: np.ndarray, speed: float, stamp: float, horizon_s: float
) -> np.ndarray:
    """Rows (t, x, y): 11 positions over ``horizon_s`` along the polyline from ``xy`` through
    the waypoints ``ahead`` at ``speed`` (clipped at its end). A robot that follows a path
    announces the path, not its current command: one that is stopped by another still shows
    where it needs to go, so the other can make way."""
    t = np.linspace(0.0, horizon_s, 11)
    pts = np.vstack([np.asarray(xy, dtype=float)[None, :], np.asarray(ahead, dtype=float)])
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    s = np.minimum(speed * t, cum[-1])
    return np.column_stack([stamp + t, np.interp(s, cum, pts[:, 0]), np.interp(s, cum, pts[:, 1])])


def own_intent(
    stamp: float,
    pose: tuple[float, float, float],
    command: tuple[float, float],
    follow: FollowState | None,
    robot: RobotSpec,
    horizon_s: float,
) -> np.ndarray:
    """What the robot announces: the path ahead of ``follow`` (the next ``INTENT_WAYPOINTS``)
    at no less than half the top speed while it is on its way along one (see
    :func:`path_intent`), else (``follow`` None or done) its current ``command`` held."""
    v, w = command
    if follow is None or follow.done:
        return intent_points(pose, v, w, stamp, horizon_s)
    ahead = follow.waypoints[follow.index : follow.index + INTENT_WAYPOINTS]
    speed = max(v, 0.5 * robot.max_vel_x)
    return path_intent(np.array(pose[:2]), ahead, speed, stamp, horizon_s)


def _rank(rid: str) -> tuple:
    """Natural order of robot ids: robot-2 before robot-10."""
    return tuple(int(p) if p.isdigit() else p for p in re.split(r"(\d+)", rid))


def gives_way(me: str, other: str) -> bool:
    """True when robot ``me`` must keep out of the way of robot ``other``."""
    return _rank(other) < _rank(me)


def intent_centres(intents: Iterable[np.ndarray], now: float, max_age_s: float) -> np.ndarray:
    """Centres (M, 2) of the discs the peers will cover: every sample of each intent from
    ``max_age_s`` ago on. An intent published longer than ``max_age_s`` ago is ignored (the
    robot stopped publishing: it is gone or its agent is stalled, and the scan still shows it)."""
    centres = [
        pts[pts[:, 0] >= now - max_age_s, 1:]
        for pts in intents
        if len(pts) and now - pts[0, 0] <= max_age_s
    ]
    centres = [c for c in centres if len(c)]
    return np.vstack(centres) if centres else np.zeros((0, 2))


def to_avoid(
    me: str,
    intents: Mapping[str, Intent],
    now: float,
    max_age_s: float,
    everyone: bool,
    skip: frozenset[str] = frozenset(),
) -> np.ndarray:
    """The centres of the discs (see :func:`intent_centres`) that the peers robot ``me`` keeps
    clear of will cover: those it gives way to (:func:`gives_way`), or all of them with
    ``everyone`` (a robot without work); none of those in ``skip``."""
    return intent_centres(
        [
            i.points
            for rid, i in intents.items()
            if rid not in skip and (everyone or gives_way(me, rid))
        ],
        now,
        max_age_s,
    )


def rim_points(centres: np.ndarray, robot_radius: float) -> np.ndarray:
    """``RIM_POINTS`` points on the rim of each disc: how a planner that keeps its centre a
    robot radius from obstacle points keeps its body off the peers' bodies."""
    angles = np.linspace(0.0, 2 * np.pi, RIM_POINTS, endpoint=False)
    rim = robot_radius * np.column_stack([np.cos(angles), np.sin(angles)])
    return (np.asarray(centres)[:, None, :] + rim[None, :, :]).reshape(-1, 2)


def peer_discs(
    intents: Iterable[np.ndarray],
    now: float,
    max_age_s: float,
    robot_radius: float,
    max_speed: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Discs that hold the peers' bodies at ``now``: centres (M, 2) at the first sample of each
    intent not older than ``max_age_s`` (where the peer was when it sent it) and radii (M,)
    of ``robot_radius`` + ``PEER_MASK_MARGIN_M`` + the way it can have driven since."""
    firsts = [pts[0] for pts in intents if len(pts) and abs(now - pts[0, 0]) <= max_age_s]
    if not firsts:
        return np.zeros((0, 2)), np.zeros(0)
    rows = np.array(firsts)
    return rows[:, 1:], robot_radius + PEER_MASK_MARGIN_M + max_speed * np.abs(now - rows[:, 0])


def without_peers(
    pose: tuple[float, float, float],
    ranges: np.ndarray,
    angle_min: float,
    angle_increment: float,
    centres: np.ndarray,
    radii: np.ndarray,
) -> np.ndarray:
    """``ranges`` of a scan taken at ``pose`` with every return that ends inside one of the
    discs (see :func:`peer_discs`) set to NaN, an invalid reading, which SLAM skips: neither a
    match nor free space is taken from a beam that hit a robot (inf, "no return", would clear
    free space along it)."""
    r = np.array(ranges, dtype=float)
    if not len(centres):
        return r
    a = pose[2] + angle_min + angle_increment * np.arange(len(r))
    with np.errstate(invalid="ignore"):
        ends = np.column_stack([pose[0] + r * np.cos(a), pose[1] + r * np.sin(a)])
    inside = (np.hypot(*(ends[:, None, :] - centres[None, :, :]).transpose(2, 0, 1)) < radii).any(
        axis=1
    )
    r[inside] = np.nan
    return r


def cut_out(
    scan: LaserScan,
    pose: tuple[float, float, float],
    intents: Mapping[str, Intent],
    max_age_s: float,
    robot: RobotSpec,
) -> LaserScan:
    """``scan``, taken at about ``pose``, with the returns off the peers' bodies cut out (see
    :func:`peer_discs` and :func:`without_peers`): what SLAM is given."""
    centres, radii = peer_discs(
        [i.points for i in intents.values()], scan.stamp, max_age_s, robot.radius, robot.max_vel_x
    )
    ranges = without_peers(pose, scan.ranges, scan.angle_min, scan.angle_increment, centres, radii)
    return replace(scan, ranges=ranges)
