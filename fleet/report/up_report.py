"""report.json of a `fleet up` run, assembled at its end from what the simulator measured (its
summary and cleaned grid), what the watcher saw (makespan, waypoints given up, time use,
messages dropped) and the coordinator's job; written with the pictures drawn from it; and the
lines that end the run's output."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fleet.dashboard.model import FINISHED_PHASES
from fleet.report.summary import (
    build_report,
    job_report,
    load_run,
    missed_breakdown,
    side_brush_only,
    time_use_of,
    write_json,
)
from fleet.rundir import write_dropped

if TYPE_CHECKING:
    from fleet.dashboard.model import FleetWatcher
    from fleet.protocol import CoverageImage, CoverageSummary
    from fleet.report.summary import RunRecorder
    from fleet.world import World


@dataclass(frozen=True)
class RunFacts:
    """What the run was, as report.json tells it: its world file, robots, speed, noise seed,
    the transits' deconfliction mode, the stored map it planned on (None: the world file), and
    what exploring first took (`fleet up --explore`; None without)."""

    world: str
    robot_count: int
    speed: float
    seed: int
    deconfliction: str
    floor_map: str | None = None
    explored: dict[str, Any] | None = None


def up_report(
    run_dir: Path,
    facts: RunFacts,
    world: World,
    summary: CoverageSummary,
    image: CoverageImage,
    watcher: FleetWatcher,
    status: str,
    wall_s: float,
) -> dict[str, Any]:
    """report.json's content for the run in ``run_dir`` that ended ``status`` after ``wall_s``
    wall seconds (the messages each process dropped written to the run dir on the way)."""
    makespan = watcher.makespan() if status in FINISHED_PHASES else None
    with watcher.lock:
        skipped = {rid: v.status.skipped for rid, v in watcher.robots.items() if v.status}
        time_use = {rid: time_use_of(v.status) for rid, v in watcher.robots.items() if v.status}
    dropped = {**watcher.dropped(), "sim": (summary.decode_errors, summary.implausible)}
    write_dropped(run_dir, dropped)
    job = job_report(run_dir / "coordinator.sqlite")
    # an agent's own count starts again with each plan: the coordinator's spans them all
    for rid, n in (job["given_up_waypoints"] or {}).items():
        skipped[rid] = max(n, skipped.get(rid) or 0)
    extra = {
        "world": facts.world,
        "robot_count": facts.robot_count,
        "speed": facts.speed,
        "seed": facts.seed,
        "deconfliction": facts.deconfliction,
        "missed": missed_breakdown(image, world.grid(image.resolution)),
        "side_brush_only": side_brush_only(image),
        "dropped": {n: {"malformed": m, "implausible": i} for n, (m, i) in dropped.items()},
        "floor_map": facts.floor_map,
        "explored": facts.explored,
        **job,
    }
    return build_report(summary, makespan, wall_s, status, extra, skipped, time_use)


def write_up_report(
    run_dir: Path,
    report: dict[str, Any],
    recorder: RunRecorder,
    image: CoverageImage,
    cleaning_width_m: float,
) -> None:
    """report.json, the recorder's last files (the cleaned grid) and the report pictures."""
    from fleet.report.figures import render_report

    write_json(run_dir / "report.json", report)
    recorder.finish(image, cleaning_width_m)
    render_report(load_run(run_dir))


def end_lines(report: dict[str, Any], run_dir: Path) -> list[str]:
    """What the run's output ends with: how it ended, its figures and files, and a line per
    piece of work left out."""
    head = (
        f"{report['status']}: coverage {100 * report['coverage']:.1f} %, repetition "
        f"{100 * report['repetition']:.1f} %, makespan {report['makespan_s']} s sim, "
        f"{report['wall_s']} s wall, collisions {report['collisions']} — "
        f"{run_dir / 'report.json'}, {run_dir / 'report.png'}"
    )
    return [head, *(f"  {left_out_line(piece)}" for piece in report.get("left_out") or [])]


def left_out_line(piece: dict[str, Any]) -> str:
    """The end text's line for a piece of report.json's ``left_out``: its id, area, where it
    lies and why no robot did it."""
    x, y = np.mean(piece["path"], axis=0)
    if piece["state"] == "stranded":
        why = "stranded: no robot left with charge"
    elif piece["blocked_by"]:
        why = f"behind {piece['blocked_by']}'s body"
    else:
        why = f"tried by {', '.join(piece['tried'])}"
    return (
        f"not reached: {piece['id']}, {piece['area_m2']:.2f} m² around ({x:.1f}, {y:.1f}) ({why})"
    )
