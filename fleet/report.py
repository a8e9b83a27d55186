"""The end-of-run report: ``report.json`` (numbers) and ``report.png`` (the cleaned floor).

The job part (``events``, ``tasks``) comes from the coordinator's state file: every event with
its sim and wall time, and per task its owners over time, rebuilt from the events.
"""

from __future__ import annotations

import json
import os
import sqlite3
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, ImageDraw

from fleet.fleet_runner import read_events
from fleet.protocol import CoverageImage, CoverageSummary

PIXELS_PER_CELL = 4
TRACK_COLOURS = [
    (31, 119, 180),
    (255, 127, 14),
    (148, 103, 189),
    (214, 39, 40),
    (23, 190, 207),
    (140, 86, 75),
]


def build_report(
    summary: CoverageSummary,
    makespan_s: float | None,
    wall_s: float,
    status: str,
    extra: dict[str, Any],
    skipped: Mapping[str, int] | None = None,
) -> dict[str, Any]:
    """The report as a JSON-ready dict. ``makespan_s`` is None when the job did not finish;
    ``skipped`` holds the waypoints each agent last reported giving up on (None: unknown)."""
    skipped = skipped or {}
    robots = {
        rid: {
            "path_length_m": round(float(summary.path_length_m[i]), 3),
            "turns": int(summary.turns[i]),
            "wall_collisions": int(summary.wall_collisions[i]),
            "robot_collisions": int(summary.robot_collisions[i]),
            "skipped_waypoints": skipped.get(rid),
        }
        for i, rid in enumerate(summary.robots)
    }
    return {
        "status": status,
        "coverage": round(summary.coverage, 5),
        "repetition": round(summary.repetition, 5),
        "makespan_s": round(makespan_s, 2) if makespan_s is not None else None,
        "sim_time_s": round(summary.stamp, 2),
        "wall_s": round(wall_s, 2),
        "cleanable_m2": round(summary.cleanable_m2, 3),
        "collisions": {
            "robot_wall": int(summary.wall_collisions.sum()),
            # each robot–robot contact is counted on both robots
            "robot_robot": int(summary.robot_collisions.sum()) // 2,
        },
        "robots": robots,
        **extra,
    }


def job_report(state: Path) -> dict[str, Any]:
    """``events`` and ``tasks`` from the coordinator's SQLite ``state`` (read-only). A task's
    ``owners`` are [robot, from, to] in sim seconds (``to`` None while it still held it at the
    end): a hold begins with an award and ends when the task is done, withdrawn, or its owner
    is lost. ``overlaps`` lists tasks held by two robots at once (it should stay empty);
    ``rejected_bids`` counts the bids the auctions ignored, by why (late, duplicate,
    malformed, not in the market)."""
    if not state.exists():
        return {"events": None, "tasks": None, "overlaps": None, "rejected_bids": None}
    db = sqlite3.connect(f"file:{state}?mode=ro", uri=True)
    try:
        meta = dict(db.execute("SELECT key, value FROM meta").fetchall())
        tasks = {
            tid: {
                "id": tid,
                "parent": parent,
                "area_m2": round(area, 3),
                "time_s": round(t_s, 1),
                "state": st,
                "owners": [],
            }
            for tid, parent, area, t_s, st in db.execute(
                "SELECT id, parent, area_m2, time_s, state FROM tasks ORDER BY rowid"
            )
        }
    finally:
        db.close()
    events = [{k: v for k, v in e.items() if k != "seq"} for e in read_events(state)]
    held: dict[str, list[Any]] = {}
    for e in events:
        kind, robot, task, sim = e["kind"], e["robot"], e["task"], round(e["sim"], 2)
        if kind in ("awarded", "reassigned") and task in tasks:
            hold = [robot, sim, None]
            tasks[task]["owners"].append(hold)
            held[task] = hold
        elif kind in ("done", "withdrawn") and task in held:
            held.pop(task)[2] = sim
        elif kind == "lost":
            for tid in [t for t, h in held.items() if h[0] == robot]:
                held.pop(tid)[2] = sim
    overlaps = [
        tid
        for tid, t in tasks.items()
        if any(
            a[2] is None or a[2] > b[1] for a, b in zip(t["owners"], t["owners"][1:], strict=False)
        )
    ]
    return {
        "events": events,
        "tasks": list(tasks.values()),
        "overlaps": overlaps,
        "rejected_bids": json.loads(meta.get("rejected_bids", "{}")),
    }


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write atomically: a crash mid-write never leaves a truncated report."""
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n")
    os.replace(tmp, path)


def render_png(
    path: Path, image: CoverageImage, tracks: dict[str, list[tuple[float, float]]]
) -> None:
    """Cleaned cells green (darker = more passes), missed cleanable cells red, the rest grey;
    each robot's true track drawn on top."""
    visits = image.visits.reshape(image.rows, image.cols)
    cleanable = image.cleanable.reshape(image.rows, image.cols).astype(bool)
    rgb = np.full((image.rows, image.cols, 3), 60, dtype=np.uint8)
    rgb[cleanable] = (230, 80, 80)
    swept = visits > 0
    shade = np.clip(255 - 40 * (visits.astype(np.int32) - 1), 90, 255).astype(np.uint8)
    rgb[swept, 0] = shade[swept] // 3
    rgb[swept, 1] = shade[swept]
    rgb[swept, 2] = shade[swept] // 3
    img = Image.fromarray(np.flipud(rgb)).resize(
        (image.cols * PIXELS_PER_CELL, image.rows * PIXELS_PER_CELL), Image.NEAREST
    )
    draw = ImageDraw.Draw(img)
    scale = PIXELS_PER_CELL / image.resolution
    height = image.rows * PIXELS_PER_CELL
    for i, (_rid, track) in enumerate(sorted(tracks.items())):
        if len(track) < 2:
            continue
        pts = [
            ((x - image.origin_x) * scale, height - (y - image.origin_y) * scale) for x, y in track
        ]
        draw.line(pts, fill=TRACK_COLOURS[i % len(TRACK_COLOURS)], width=2)
    img.save(path)
