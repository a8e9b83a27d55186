"""`fleet bench follow`: one robot drives the coordinator's whole coverage tour, in one process.

What a live agent does on each scan, without the bus: the simulator core (``SimCore``: physics,
noisy lidar and odometry, the ground-truth cleaning grid) steps; each scan goes to the robot's
pose source (its own SLAM, as in ``fleet up``, or the true pose); the path follower
(``agents.follow.motion.follow_step``: DWA, turns in place, escapes, give-up) computes the command
from the pose predicted ``latency_s`` ahead, and the command takes effect that much later (0
by default: at ``--speed 0`` the live simulator waits for each answer, and a one-robot
``fleet up`` of the small world matched the default within 4 % in time, coverage and time by
kind; a real-time run lags up to ``sim.max_lag_s``). The plan is the coordinator's: the tour
of ``TaskPlanner.tasks()`` driven from the robot's start (``TaskPlanner.drive``).

It isolates what the plan and the follower lose on the floor from what peers, the market and
the processes cost, and is deterministic for a seed, so changes to the follower or the plan
can be judged over many seeds and maps quickly. Per run: coverage and repetition (the
simulator's grid), sim time against the plan's estimate, contacts (with where they were),
waypoints given up (with where), the tracking error of the sweep (distance of the true centre
from the planned segment), the cross-track error on lanes (the true centre's distance across
the lane, where the follower sweeps a segment the tour labels a lane, ``planners.tour_elements``,
and the centre is abreast of it: what the lanes' overlap has to absorb), and the sim seconds per
kind of control step; each contact is given with the kind of the control step in force when it
happened (edge: the wall follower's).
"""

from __future__ import annotations

import contextlib
import time
from pathlib import Path
from typing import Any

import numpy as np

from agents.control import scan_points
from agents.follow.motion import follow_step, predict
from agents.follow.state import FollowParams, Situation
from agents.follow.track import tracked
from agents.pose_source import SlamPose
from agents.time_use import step_kind
from fleet.coordinator.planning import TaskPlanner
from fleet.params import FleetConfig
from fleet.protocol import TIME_KINDS
from fleet.world import World
from planners.tour_elements import LANE, TourElements
from sim_server.core import SimCore
from sim_server.recorder import CarmenRecorder

ROBOT = "robot-0"


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    denom = float(ab @ ab)
    t = 0.0 if denom == 0 else min(max(float((p - a) @ ab) / denom, 0.0), 1.0)
    return float(np.hypot(*(p - (a + t * ab))))


def _cross_track(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float | None:
    """The distance of ``p`` across the line through segment ``a``–``b``, or None when ``p``
    is not abreast of the segment (its foot falls outside it)."""
    ab = b - a
    length = float(np.hypot(*ab))
    if length == 0:
        return None
    along = float((p - a) @ ab) / length
    if along < 0 or along > length:
        return None
    return abs(float(ab[0] * (p - a)[1] - ab[1] * (p - a)[0])) / length


def _lane_segments(
    waypoints: np.ndarray, sweep_from: int, elements: TourElements | None
) -> np.ndarray:
    """Per waypoint segment, whether the tour labels it a lane: the sweeps from ``sweep_from``
    on are the tour itself (its tasks one after the other), so a segment's midpoint lies at
    its own arc length from there."""
    n = max(len(waypoints) - 1, 0)
    out = np.zeros(n, dtype=bool)
    if elements is None or n <= sweep_from:
        return out
    seg = np.hypot(*np.diff(waypoints, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    mid = (cum[sweep_from:-1] + cum[sweep_from + 1 :]) / 2 - cum[sweep_from]
    i = elements.at(mid)
    out[sweep_from:] = (i >= 0) & (elements.kind[np.clip(i, 0, None)] == LANE)
    return out


def _figures(errors: list[float]) -> dict[str, float]:
    e = np.array(errors) if errors else np.zeros(1)
    return {
        "mean": round(float(e.mean()), 4),
        "p95": round(float(np.percentile(e, 95)), 4),
        "max": round(float(e.max()), 4),
    }


def follow_tour(
    world: World,
    cfg: FleetConfig,
    seed: int,
    pose_source: str = "slam",
    latency_s: float = 0.0,
    time_factor: float = 4.0,
    record: Path | None = None,
) -> dict[str, Any]:
    """Drive the whole tour once; stops when the plan is done or after ``time_factor`` times
    the plan's estimate (plus a minute). With ``record``, the run's scans and odometry are
    written there as a CARMEN log, the true poses beside it (:mod:`sim_server.recorder`), so
    that ``fleet slam replay`` scores the SLAM on the coverage tour itself."""
    if pose_source not in ("slam", "truth"):
        raise ValueError(f"pose source must be slam or truth, not {pose_source!r}")
    wall0 = time.perf_counter()
    planner = TaskPlanner(world, cfg)
    tasks = planner.tasks()
    start = tuple(float(v) for v in world.start_poses(1, cfg.robot.radius)[0])
    waypoints, starts = planner.drive(start[:2], [(t, False) for t in tasks])
    sweep_from = starts[0]
    raw = planner.meta.get("tour_elements")
    on_lane = _lane_segments(waypoints, sweep_from, TourElements.from_json(raw) if raw else None)
    estimate = sum(t.time_s for t in tasks)
    core = SimCore(world, cfg, seed=seed)
    core.add_robot(ROBOT, start)
    slam = (
        SlamPose(cfg.slam, start, cfg.lidar.range_min, cfg.lidar.range_max)
        if pose_source == "slam"
        else None
    )
    params = FollowParams.of(cfg)
    follow = tracked(waypoints, sweep_from, params)
    command = (0.0, 0.0)
    pending: list[tuple[float, float, float]] = []
    velocity = (0.0, 0.0)
    dt = params.dt
    time_use = dict.fromkeys(TIME_KINDS, 0.0)
    tracking: list[float] = []
    cross: list[float] = []
    contacts: list[tuple[float, float, float]] = []
    given_up: list[tuple[float, float]] = []
    limit = time_factor * estimate + 60.0
    finished_at = None
    kind = "idle"
    with contextlib.ExitStack() as stack:
        recorder = (
            stack.enter_context(CarmenRecorder(record, ROBOT, f"fleet bench follow: {world.name}"))
            if record is not None
            else None
        )
        while core.t < limit:
            out = core.step()
            if recorder is not None:
                recorder.record(out.odometry, out.scans, core.truth)
            contacts += [
                (round(c.stamp, 1), round(c.x, 3), round(c.y, 3), kind) for c in out.collisions
            ]
            while pending and pending[0][0] <= core.t + 1e-9:
                _, v, w = pending.pop(0)
                core.set_cmd(ROBOT, v, w)
            for _, odom in out.odometry:
                velocity = (odom.v, odom.w)
                if slam is not None:
                    slam.on_odometry(odom)
            for _, scan in out.scans:
                if slam is not None:
                    slam.on_scan(scan)
                    pose = slam.pose()
                else:
                    pose = core.truth()[ROBOT]
                obstacles = scan_points(pose, scan.ranges, scan.angle_min, scan.angle_increment)
                before = follow
                ahead = predict(pose, command, latency_s)
                follow, result = follow_step(
                    follow, Situation(ahead, velocity, obstacles, np.zeros((0, 2))), params
                )
                kind = step_kind(before, follow, sweep_from)
                time_use[kind] += dt
                if follow.skipped > before.skipped:
                    wp = before.waypoints[before.index]
                    given_up.append((round(float(wp[0]), 3), round(float(wp[1]), 3)))
                if kind == "sweep" and 0 < follow.index < len(waypoints):
                    truth_xy = np.array(core.truth()[ROBOT][:2])
                    a, b = waypoints[follow.index - 1], waypoints[follow.index]
                    tracking.append(_segment_distance(truth_xy, a, b))
                    across = _cross_track(truth_xy, a, b) if on_lane[follow.index - 1] else None
                    if across is not None:
                        cross.append(across)
                command = (0.0, 0.0) if result is None else (result.v, result.w)
                pending.append((scan.stamp + latency_s, *command))
                if result is None and finished_at is None:
                    finished_at = core.t
            if finished_at is not None:
                break
    summary = core.summary(time.perf_counter() - wall0)
    return {
        "world": world.name,
        "seed": seed,
        "pose_source": pose_source,
        "finished": finished_at is not None,
        "coverage": round(summary.coverage, 5),
        "repetition": round(summary.repetition, 5),
        "sim_s": round(core.t, 1),
        "plan_estimate_s": round(estimate, 1),
        "time_over_estimate": round(core.t / estimate, 3) if estimate > 0 else None,
        "contacts": len(contacts),
        "contact_points": contacts,
        "given_up": len(given_up),
        "given_up_points": given_up,
        "tracking_m": _figures(tracking),
        "lane_cross_track_m": {**_figures(cross), "steps": len(cross)},
        "time_s": {k: round(v, 1) for k, v in time_use.items()},
        "path_m": round(float(summary.path_length_m[0]), 2),
        "wall_s": round(time.perf_counter() - wall0, 1),
    }


def summarize(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Per world: medians of coverage, repetition and time over estimate; totals of contacts
    and waypoints given up; the worst tracking error and the worst cross-track error on lanes
    (p95 of each run)."""
    out: dict[str, Any] = {}
    for name in dict.fromkeys(r["world"] for r in runs):
        mine = [r for r in runs if r["world"] == name]
        out[name] = {
            "runs": len(mine),
            "finished": sum(r["finished"] for r in mine),
            "coverage": round(float(np.median([r["coverage"] for r in mine])), 5),
            "repetition": round(float(np.median([r["repetition"] for r in mine])), 5),
            "time_over_estimate": round(
                float(np.median([r["time_over_estimate"] for r in mine])), 3
            ),
            "contacts": sum(r["contacts"] for r in mine),
            "given_up": sum(r["given_up"] for r in mine),
            "tracking_p95_m": round(max(r["tracking_m"]["p95"] for r in mine), 4),
            "lane_cross_track_p95_m": round(max(r["lane_cross_track_m"]["p95"] for r in mine), 4),
        }
    return out


def run_line(r: dict[str, Any]) -> str:
    t = r["time_s"]
    return (
        f"{r['world']} seed {r['seed']}: {'done' if r['finished'] else 'NOT finished'} in "
        f"{r['sim_s']} s sim (plan {r['plan_estimate_s']} s, ×{r['time_over_estimate']}), "
        f"coverage {100 * r['coverage']:.1f} %, repetition {100 * r['repetition']:.1f} %, "
        f"contacts {r['contacts']} {r['contact_points'][:3]}, given up {r['given_up']} "
        f"{r['given_up_points'][:3]}, tracking p95 {100 * r['tracking_m']['p95']:.1f} cm, "
        f"across lanes p95 {100 * r['lane_cross_track_m']['p95']:.1f} cm; "
        + ", ".join(f"{k} {t[k]:.0f}" for k in TIME_KINDS if t[k] > 0)
        + f" s; {r['wall_s']} s wall"
    )
