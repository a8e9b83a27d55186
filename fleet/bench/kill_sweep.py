"""`fleet bench recovery --sweep N`: one robot killed at N moments spread over the job.

A robot can die anywhere: beside the dock, in a doorway, in the pocket another robot works in.
Each of N runs of ``fleet up --speed 0 --until-done`` SIGKILLs the victim's agent
``k / (N + 1)`` of the no-failure run's makespan (k = 1 … N) after the job's first award (the
makespan's own start); with
``respawn_after_s`` its agent is respawned that many sim seconds later. Its body stays where
it stopped, so the floor under it cannot be cleaned: ``coverage_outside_body`` leaves the
cleanable cells within the robot's radius (plus the track's 5 cm resolution) of its last true
position out of the cleanable area. Per moment: the run's status, coverage, makespan and its
ratio to the no-failure run, contacts, waypoints given up, the robots' escape time (sim
seconds in the escape move, how stuck robots show) and the coordinator's ``stuck`` and
``unreachable`` events.
"""

from __future__ import annotations

import signal
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from fleet.params import load_fleet_config
from fleet.report.summary import ReportError, load_run
from fleet.supervisor.runner import RunningFleet

TRACK_STEP_M = 0.05


def body_mask(
    visits: np.ndarray,
    resolution: float,
    origin: tuple[float, float],
    xy: tuple[float, float],
    radius: float,
) -> np.ndarray:
    """Cells of a coverage grid whose centres lie within ``radius`` of ``xy``."""
    rows, cols = visits.shape
    x = origin[0] + (np.arange(cols) + 0.5) * resolution
    y = origin[1] + (np.arange(rows) + 0.5) * resolution
    return np.hypot(x[None, :] - xy[0], y[:, None] - xy[1]) <= radius


def outside_body(run_dir: Path, victim: str, radius: float) -> float | None:
    """Coverage of the cleanable floor not under ``victim``'s body (its last true position)."""
    try:
        run = load_run(run_dir)
    except ReportError:
        return None
    track = run.tracks.get(victim)
    if track is None or not len(track):
        return None
    under = body_mask(
        run.visits, run.resolution, run.origin, tuple(track[-1, 1:]), radius + TRACK_STEP_M
    )
    floor = run.cleanable & ~under
    return round(float((run.swept & floor).sum() / max(floor.sum(), 1)), 4)


def _one(
    root: Path,
    world: str,
    robots: int,
    seed: int,
    victim: str,
    at_s: float,
    respawn_after_s: float | None,
) -> tuple[Path, dict[str, Any], float]:
    name = f"kill-{at_s:06.1f}" + ("-respawn" if respawn_after_s is not None else "")
    fleet = RunningFleet(root / name, world, robots, seed)
    clock = fleet.clock()
    killed_at = float("nan")
    try:
        fleet.wait(lambda: fleet.first_award() is not None, 900.0, poll=0.1)
        start = fleet.first_award() or 0.0
        fleet.wait(lambda: clock.t >= start + at_s, 900.0, poll=0.01)
        killed_at = clock.t
        fleet.signal(victim, signal.SIGKILL)
        if respawn_after_s is not None:
            fleet.wait(lambda: clock.t >= killed_at + respawn_after_s, 900.0, poll=0.01)
            fleet.verb("respawn", victim)
        report = fleet.finish() or {}
    finally:
        fleet.cleanup()
    return root / name, report, killed_at


def _moment(
    run_dir: Path,
    report: dict[str, Any],
    killed_at: float,
    base_makespan: float,
    victim: str,
    radius: float,
    respawned: bool,
) -> dict[str, Any]:
    robots = report.get("robots", {})
    events = report.get("events", [])
    makespan = report.get("makespan_s")
    return {
        "kill_sim_s": round(killed_at, 1),
        "respawned": respawned,
        "status": report.get("status"),
        "coverage": report.get("coverage"),
        "coverage_outside_body": None if respawned else outside_body(run_dir, victim, radius),
        "repetition": report.get("repetition"),
        "makespan_s": makespan,
        "makespan_ratio": round(makespan / base_makespan, 3) if makespan else None,
        "contacts": report.get("collisions"),
        "given_up": sum(r.get("skipped_waypoints", 0) for r in robots.values()),
        "escape_s": round(sum(r.get("time_s", {}).get("escape", 0.0) for r in robots.values()), 1),
        "stuck_events": sum(e.get("kind") == "stuck" for e in events),
        "unreachable": report.get("unreachable"),
        "run_dir": str(run_dir),
    }


def sweep(
    root: Path,
    world: str,
    robots: int,
    seed: int,
    moments: int,
    respawn_after_s: float | None,
    base: dict[str, Any],
    progress: Callable[[str], None],
    victim: str = "robot-1",
) -> list[dict[str, Any]]:
    """The victim killed at ``moments`` moments of the no-failure run ``base`` (its report)."""
    base_makespan = float(base["makespan_s"])
    radius = load_fleet_config().robot.radius
    out = []
    for k in range(1, moments + 1):
        at_s = base_makespan * k / (moments + 1)
        label = "killed and respawned" if respawn_after_s is not None else "killed"
        progress(f"[{k}/{moments}] {victim} {label} at {at_s:.1f} s sim")
        run_dir, report, killed_at = _one(root, world, robots, seed, victim, at_s, respawn_after_s)
        row = _moment(
            run_dir, report, killed_at, base_makespan, victim, radius, respawn_after_s is not None
        )
        progress(
            f"    {row['status']}: coverage {row['coverage']} (outside the body "
            f"{row['coverage_outside_body']}), makespan ×{row['makespan_ratio']}, "
            f"contacts {row['contacts']}, given up {row['given_up']}, escape {row['escape_s']} s"
        )
        out.append(row)
    return out


def sweep_lines(rows: list[dict[str, Any]]) -> list[str]:
    """The per-moment table."""
    lines = [
        "kill at (s)  status      coverage  outside body  makespan ×  contacts  given up  "
        "escape (s)  stuck"
    ]
    for r in rows:
        c = r["contacts"] or {}
        lines.append(
            f"{r['kill_sim_s']:>10}  {r['status']!s:<10}  {r['coverage']!s:>8}  "
            f"{r['coverage_outside_body']!s:>12}  {r['makespan_ratio']!s:>10}  "
            f"{c.get('robot_wall', '?')}/{c.get('robot_robot', '?'):<6}  {r['given_up']:>8}  "
            f"{r['escape_s']:>10}  {r['stuck_events']:>5}"
        )
    return lines
