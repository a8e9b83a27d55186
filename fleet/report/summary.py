"""The end-of-run report: ``report.json`` (numbers) and the data its pictures are drawn from.

The job part (``events``, ``tasks``) comes from the coordinator's state file: every event with
its sim and wall time, and per task its owners over time, rebuilt from the events.

``fleet up`` also writes, beside ``report.json``, what the pictures (``fleet.report.figures``)
need, so ``fleet report RUN_DIR`` can draw them again from the run dir alone:

The files but the grid are written as the run goes, a line at a time (``RunRecorder``): a run
that dies leaves what it heard so far readable.

* ``coverage.npz``: the simulator's final cleaning grid (the main brushes' visits, the cells
  side brushes touched (``side``, all false without them; absent before side brushes) and the
  cleanable cells, row 0 at ``origin_y``), its resolution and origin in metres, and the brush
  width;
* ``tracks.csv``: ``sim_s,robot,x,y``, each robot's true position every ``TRACK_STEP_M``
  (1.25 cm; 5 cm before report format 2), the robots' rows interleaved in the order heard
  (grouped by robot before the files were written as the run went);
* ``coverage.csv``: ``sim_s,coverage,repetition``, the fleet's cleaning over time;
* ``collisions.csv``: ``sim_s,kind,robot,other,x,y``, every contact;
* ``status.csv``: ``sim_s,robot,plan_id,waypoint`` and the sim seconds per kind of control
  step (``fleet.protocol.TIME_KINDS``) of every status an agent sent: the plan it drove, the
  waypoint it headed for, and (from the growth of those sums) what it was doing when; rows in
  the order heard (``fleet.report.repetition.read_status`` sorts each robot's by time);
* ``plans.jsonl``: every plan the coordinator sent, one JSON object a line (``sim_s``,
  ``robot``, ``plan_id``, ``task``, ``sweep_from``, ``chain``, ``chain_starts``,
  ``waypoints``).

The last two (since report format 2) are what ``fleet bench repetition`` charges each
re-entry of the brush with (``fleet.report.repetition``).
"""

from __future__ import annotations

import csv
import json
import os
import sqlite3
import threading
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fleet.plausible import StampWatch
from fleet.protocol import (
    TIME_KINDS,
    Clock,
    Collision,
    CoverageImage,
    CoverageSummary,
    Plan,
    RobotStatus,
    TruthPose,
)
from fleet.rundir import read_json_object
from fleet.supervisor.runner import read_events
from planners.coverage.metrics import missed_by_clearance
from planners.grid import GridMap, clearance

if TYPE_CHECKING:
    from fleet.bus import Bus

REPORT_FILE = "report.json"
GRID_FILE = "coverage.npz"
TRACKS_FILE = "tracks.csv"
COVERAGE_FILE = "coverage.csv"
COLLISIONS_FILE = "collisions.csv"
STATUS_FILE = "status.csv"
PLANS_FILE = "plans.jsonl"
# report.json's format: 2 added the tour's own figures (``plan``) and the files status.csv and
# plans.jsonl
REPORT_FORMAT = 2
# a robot's track keeps a true position when it is this far (L1) from the last one kept: a
# quarter of the simulator's 5 cm cleaning cell, the rule by which the simulator moves a
# brush (``sim_server.cleaning.CleaningGrid.update``, at the rate truth is sent), so the
# track replays the simulator's own cleaning
TRACK_STEP_M = 0.0125
TRACK_COLUMNS = ("sim_s", "robot", "x", "y")
COVERAGE_COLUMNS = ("sim_s", "coverage", "repetition")
COLLISION_COLUMNS = ("sim_s", "kind", "robot", "other", "x", "y")
STATUS_COLUMNS = ("sim_s", "robot", "plan_id", "waypoint", *TIME_KINDS)
# report.json's "missed" splits the floor never cleaned by its clearance from walls and
# furniture: under 0.1 m only a pass hugging them sweeps, beyond 0.3 m it is open floor
MISSED_BANDS_M = (0.1, 0.3)
MISSED_BANDS = ("under_0.1m", "0.1_to_0.3m", "over_0.3m")
# the coordinator's task states of work no robot could do (fleet.coordinator.job.LEFT_OUT)
LEFT_OUT_STATES = ("blocked", "unreachable", "stranded")
# report.json fields the pictures read, and their JSON types
REPORT_FIELDS: dict[str, type | tuple[type, ...]] = {
    "status": str,
    "coverage": (int, float),
    "repetition": (int, float),
    "sim_time_s": (int, float),
    "wall_s": (int, float),
    "cleanable_m2": (int, float),
    "collisions": dict,
    "robots": dict,
}


def time_use_of(status: RobotStatus) -> dict[str, float] | None:
    """An agent's reported seconds per kind of control step, by name (None from an agent that
    does not report them)."""
    if len(status.time_s) != len(TIME_KINDS):
        return None
    return {k: round(float(t), 1) for k, t in zip(TIME_KINDS, status.time_s, strict=True)}


def missed_breakdown(image: CoverageImage, grid: GridMap) -> dict[str, float] | None:
    """report.json's ``missed``: the cleanable floor never cleaned, as fractions of the
    cleanable area, by clearance from walls and furniture (``MISSED_BANDS``; they sum to 1 −
    coverage). ``grid`` is the world's occupancy at the simulator's cleaning resolution; None
    when it is not the image's grid."""
    shape = (image.rows, image.cols)
    same = (
        grid.shape == shape
        and abs(grid.resolution - image.resolution) < 1e-9
        and np.allclose(grid.origin, (image.origin_x, image.origin_y))
    )
    if not same:
        return None
    parts = missed_by_clearance(
        image.swept(),
        image.cleanable.reshape(shape).astype(bool),
        clearance(grid),
        MISSED_BANDS_M,
    )
    return {name: round(part, 5) for name, part in zip(MISSED_BANDS, parts, strict=True)}


def side_brush_only(image: CoverageImage) -> float:
    """report.json's ``side_brush_only``: the share of the cleanable floor that only a side
    brush swept (the main brushes never passed over it); 0 without side brushes."""
    cleanable = image.cleanable.reshape(image.rows, image.cols).astype(bool)
    only = cleanable & image.side_mask() & (image.visits.reshape(cleanable.shape) == 0)
    return round(float(only.sum()) / max(int(cleanable.sum()), 1), 5)


def battery_of(summary: CoverageSummary, i: int) -> dict[str, dict[str, Any]]:
    """report.json's ``battery`` of robot ``i`` of ``summary``, as the simulator kept it: its
    lowest charge (fraction of a full one), the charges it began on a dock, its seconds on one
    and whether it stood on one when the job ended (``parked``); nothing with batteries off."""
    if i >= len(summary.charge):
        return {}
    return {
        "battery": {
            "min_charge": round(float(summary.min_charge[i]), 4),
            "charges": int(summary.charges[i]),
            "charging_s": round(float(summary.charging_s[i]), 1),
            "parked": bool(summary.docked[i]),
        }
    }


def build_report(
    summary: CoverageSummary,
    makespan_s: float | None,
    wall_s: float,
    status: str,
    extra: dict[str, Any],
    skipped: Mapping[str, int] | None = None,
    time_use: Mapping[str, Mapping[str, float]] | None = None,
) -> dict[str, Any]:
    """The report as a JSON-ready dict. ``makespan_s`` is None when the job did not finish;
    ``skipped`` holds the waypoints each agent last reported giving up on, and ``time_use`` the
    sim seconds it last reported per kind of control step (``fleet.protocol.TIME_KINDS``);
    None where unknown."""
    skipped = skipped or {}
    time_use = time_use or {}
    robots = {
        rid: {
            "path_length_m": round(float(summary.path_length_m[i]), 3),
            "turns": int(summary.turns[i]),
            "wall_collisions": int(summary.wall_collisions[i]),
            "robot_collisions": int(summary.robot_collisions[i]),
            "skipped_waypoints": skipped.get(rid),
            "time_s": time_use.get(rid),
            **battery_of(summary, i),
        }
        for i, rid in enumerate(summary.robots)
    }
    return {
        "format": REPORT_FORMAT,
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
    malformed, not in the market); ``plan_estimate_s`` is the makespan the first allocation
    priced (the longest of the winners' committed times; with batteries, its regions worked
    with the charges they need, ``planners.battery.makespan_with_charging``), None if it never
    completed;
    ``given_up_waypoints`` the waypoints each robot gave up over all its plans, as the
    coordinator counted them (robots that gave up none are left out); ``left_out`` the work no
    robot could do (state ``blocked``: under or behind the body of ``blocked_by``; or
    ``unreachable``: every robot in ``tried`` tried it; or ``stranded``: left open because no
    robot could work any more, each lost or out of charge), each with its area and path, and
    ``left_out_m2`` their area; ``plan`` the one-robot tour's own figures as the coordinator
    computed them when it planned (``fleet.coordinator.planning.tour_figures``)."""
    if not state.exists():
        return {
            "plan": None,
            "events": None,
            "tasks": None,
            "overlaps": None,
            "rejected_bids": None,
            "plan_estimate_s": None,
            "given_up_waypoints": None,
            "left_out": None,
            "left_out_m2": None,
        }
    db = sqlite3.connect(f"file:{state}?mode=ro", uri=True)
    try:
        meta = dict(db.execute("SELECT key, value FROM meta").fetchall())
        rows = db.execute(
            "SELECT id, parent, area_m2, time_s, state, path, tried, blocked_by FROM tasks "
            "ORDER BY rowid"
        ).fetchall()
    finally:
        db.close()
    tasks = {
        tid: {
            "id": tid,
            "parent": parent,
            "area_m2": round(area, 3),
            "time_s": round(t_s, 1),
            "state": st,
            "owners": [],
        }
        for tid, parent, area, t_s, st, *_ in rows
    }
    left_out = [
        {
            "id": tid,
            "state": st,
            "area_m2": round(area, 3),
            "blocked_by": by,
            "tried": json.loads(tried or "[]"),
            "path": np.frombuffer(path, dtype="<f8").reshape(-1, 2).round(3).tolist(),
        }
        for tid, _, area, _, st, path, tried, by in rows
        if st in LEFT_OUT_STATES
    ]
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
        elif kind in ("lost", "stuck"):
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
        "plan": json.loads(meta.get("tour", "null")),
        "events": events,
        "tasks": list(tasks.values()),
        "overlaps": overlaps,
        "rejected_bids": json.loads(meta.get("rejected_bids", "{}")),
        "plan_estimate_s": json.loads(meta.get("estimate_s", "null")),
        "given_up_waypoints": json.loads(meta.get("given_up_waypoints", "{}")).get("by_robot", {}),
        "left_out": left_out,
        "left_out_m2": round(sum(t["area_m2"] for t in left_out), 3),
    }


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write atomically: a crash mid-write never leaves a truncated report."""
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n")
    os.replace(tmp, path)


class ReportError(Exception):
    """A run dir the report cannot be drawn from; the message names the file and field."""


class RunRecorder:
    """Records, during a run, what the report pictures need and the live view does not keep:
    true tracks with their sim times, the fleet's coverage over time, the contacts, the
    statuses and the plans. Each goes to its file in the run dir as it comes, a line at a time
    (append-only, line-buffered), so its memory does not grow with the run and a run that dies
    leaves every line heard so far readable; ``finish`` adds the cleaning grid."""

    def __init__(self, bus: Bus, clock_step_s: float, run_dir: Path) -> None:
        """``clock_step_s``: how far past the sim clock (``fleet.plausible.Bounds``) a message
        may be stamped before it is dropped (``watch``, shared with the live view); statuses of
        robots whose liveliness token it never heard are dropped too."""
        self.lock = threading.Lock()
        self.watch = StampWatch(clock_step_s, bus.drop_implausible, bus.keys.clock())
        self.run_dir = run_dir
        self._files = {
            name: (run_dir / name).open("w", newline="", buffering=1)
            for name in (TRACKS_FILE, COVERAGE_FILE, COLLISIONS_FILE, STATUS_FILE, PLANS_FILE)
        }
        self._csv = {
            name: csv.writer(self._files[name])
            for name in (TRACKS_FILE, COVERAGE_FILE, COLLISIONS_FILE, STATUS_FILE)
        }
        for name, header in (
            (TRACKS_FILE, TRACK_COLUMNS),
            (COVERAGE_FILE, COVERAGE_COLUMNS),
            (COLLISIONS_FILE, COLLISION_COLUMNS),
            (STATUS_FILE, STATUS_COLUMNS),
        ):
            self._csv[name].writerow(header)
        self._last_point: dict[str, tuple[float, float]] = {}
        self._last_coverage = -np.inf
        self._robot_of = bus.keys.robot_of
        bus.subscribe(bus.keys.clock(), Clock, self.watch.hear_clock)
        bus.subscribe(bus.keys.all_robots("truth"), TruthPose, self._on_truth)
        bus.subscribe(bus.keys.coverage(), CoverageSummary, self._on_coverage)
        bus.subscribe(bus.keys.collisions(), Collision, self._on_collision)
        bus.subscribe(bus.keys.all_robots("status"), RobotStatus, self._on_status)
        bus.subscribe(bus.keys.plan("*"), Plan, self._on_plan)
        bus.watch_alive("agent", self.watch.join, self.watch.join)

    def _row(self, name: str, row: tuple[Any, ...]) -> None:
        """Append one CSV row (floats to 4 decimals); the caller holds the lock."""
        if not self._files[name].closed:
            self._csv[name].writerow([round(v, 4) if isinstance(v, float) else v for v in row])

    def _on_truth(self, key: str, m: TruthPose) -> None:
        if self.watch.ahead(key, "sim", m.stamp):
            return
        rid = self._robot_of(key)
        with self.lock:
            last = self._last_point.get(rid)
            if last is None or abs(last[0] - m.x) + abs(last[1] - m.y) >= TRACK_STEP_M:
                self._last_point[rid] = (m.x, m.y)
                self._row(TRACKS_FILE, (m.stamp, rid, m.x, m.y))

    def _on_coverage(self, key: str, m: CoverageSummary) -> None:
        if self.watch.ahead(key, "sim", m.stamp):
            return
        with self.lock:
            if m.stamp > self._last_coverage:
                self._last_coverage = m.stamp
                self._row(COVERAGE_FILE, (m.stamp, m.coverage, m.repetition))

    def _on_collision(self, key: str, m: Collision) -> None:
        if self.watch.ahead(key, "sim", m.stamp):
            return
        with self.lock:
            self._row(COLLISIONS_FILE, (m.stamp, m.kind, m.robot, m.other, m.x, m.y))

    def _on_status(self, key: str, m: RobotStatus) -> None:
        rid = self._robot_of(key)
        if len(m.time_s) != len(TIME_KINDS):
            return
        if self.watch.stranger(key, rid) or self.watch.ahead(key, rid, m.stamp):
            return
        with self.lock:
            self._row(STATUS_FILE, (m.stamp, rid, m.plan_id, m.waypoint, *m.time_s.tolist()))

    def _on_plan(self, key: str, m: Plan) -> None:
        if self.watch.ahead(key, "coordinator", m.stamp):
            return
        record = {
            "sim_s": round(m.stamp, 4),
            "robot": key.rsplit("/", 1)[-1],
            "plan_id": m.plan_id,
            "task": m.task,
            "sweep_from": m.sweep_from,
            "chain": list(m.chain),
            "chain_starts": m.chain_starts.tolist(),
            # exact: the tasks' paths in the job's store are the same floats
            "waypoints": m.waypoints.tolist(),
        }
        with self.lock:
            if not self._files[PLANS_FILE].closed:
                self._files[PLANS_FILE].write(json.dumps(record) + "\n")

    def finish(self, image: CoverageImage, cleaning_width_m: float) -> None:
        """Close the recorded files and write the cleaning grid beside them."""
        self.close()
        write_grid(self.run_dir / GRID_FILE, image, cleaning_width_m)

    def close(self) -> None:
        """Stop recording: what came so far is on disk; later messages are not recorded."""
        with self.lock:
            for f in self._files.values():
                f.close()


def write_grid(path: Path, image: CoverageImage, cleaning_width_m: float) -> None:
    """The cleaning grid as ``coverage.npz`` (see the module docstring)."""
    shape = (image.rows, image.cols)
    with path.open("wb") as f:
        np.savez_compressed(
            f,
            visits=image.visits.reshape(shape),
            side=image.side_mask(),
            cleanable=image.cleanable.reshape(shape).astype(bool),
            resolution=image.resolution,
            origin=np.array([image.origin_x, image.origin_y]),
            cleaning_width_m=cleaning_width_m,
        )


@dataclass
class RunData:
    """Everything the report pictures are drawn from, read back from a run dir."""

    run_dir: Path
    report: dict[str, Any]
    visits: np.ndarray
    cleanable: np.ndarray
    resolution: float
    origin: tuple[float, float]
    cleaning_width_m: float
    side: np.ndarray | None = None
    tracks: dict[str, np.ndarray] = field(default_factory=dict)
    coverage: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    collisions: list[dict[str, Any]] = field(default_factory=list)

    @property
    def swept(self) -> np.ndarray:
        """The cells either brush swept: the main brushes' visits and the side brushes'."""
        return (self.visits > 0) if self.side is None else (self.visits > 0) | self.side

    @property
    def robots(self) -> list[str]:
        """Every robot of the run: those in report.json and those with a track."""
        return sorted(set(self.report["robots"]) | set(self.tracks))

    @property
    def events(self) -> list[dict[str, Any]]:
        return self.report.get("events") or []


def load_run(run_dir: Path) -> RunData:
    """Read a run dir written by ``fleet up``; raises ReportError naming the file and field."""
    if not run_dir.is_dir():
        raise ReportError(f"no such run dir: {run_dir}")
    report = _read_report(run_dir / REPORT_FILE)
    grid = _read_grid(run_dir / GRID_FILE)
    coverage = [
        tuple(_number(row, k, run_dir / COVERAGE_FILE, line) for k in COVERAGE_COLUMNS)
        for line, row in read_csv(run_dir / COVERAGE_FILE, COVERAGE_COLUMNS)
    ]
    collisions = []
    for line, row in read_csv(run_dir / COLLISIONS_FILE, COLLISION_COLUMNS):
        path = run_dir / COLLISIONS_FILE
        collisions.append(
            {
                **row,
                **{k: _number(row, k, path, line) for k in ("sim_s", "x", "y")},
            }
        )
    return RunData(
        run_dir=run_dir,
        report=report,
        tracks=read_tracks(run_dir / TRACKS_FILE),
        coverage=np.array(coverage, dtype=float).reshape(-1, 3),
        collisions=collisions,
        **grid,
    )


def read_tracks(path: Path) -> dict[str, np.ndarray]:
    """Each robot's track from ``tracks.csv``: rows (sim s, x, y) in the order recorded."""
    tracks: dict[str, list[tuple[float, float, float]]] = {}
    for line, row in read_csv(path, TRACK_COLUMNS):
        t, x, y = (_number(row, k, path, line) for k in ("sim_s", "x", "y"))
        tracks.setdefault(row["robot"], []).append((t, x, y))
    return {rid: np.array(tr, dtype=float).reshape(-1, 3) for rid, tr in tracks.items()}


def _read_report(path: Path) -> dict[str, Any]:
    if not path.exists():
        raise ReportError(f"{path} does not exist: `fleet up` writes it when a run ends")
    raw = read_json_object(path, ReportError)
    for key, kind in REPORT_FIELDS.items():
        if key not in raw:
            raise ReportError(f"{path}: missing field {key}")
        if not isinstance(raw[key], kind) or isinstance(raw[key], bool):
            raise ReportError(f"{path}: field {key} has the wrong type: {raw[key]!r}")
    events = raw.get("events")
    if events is not None and not (
        isinstance(events, list)
        and all(isinstance(e, dict) and {"sim", "kind", "robot"} <= e.keys() for e in events)
    ):
        raise ReportError(f"{path}: field events must be a list of {{sim, kind, robot, ...}}")
    return raw


def _read_grid(path: Path) -> dict[str, Any]:
    try:
        with np.load(path) as npz:
            visits = np.asarray(npz["visits"])
            side = np.asarray(npz["side"]).astype(bool) if "side" in npz else None
            cleanable = np.asarray(npz["cleanable"]).astype(bool)
            resolution = float(npz["resolution"])
            origin = np.asarray(npz["origin"], dtype=float)
            width = float(npz["cleaning_width_m"])
    except FileNotFoundError:
        raise ReportError(f"{path} does not exist: `fleet up` writes it when a run ends") from None
    except KeyError as e:
        raise ReportError(f"{path}: missing array {e.args[0]}") from None
    except (OSError, ValueError, TypeError, zipfile.BadZipFile) as e:
        raise ReportError(f"{path} is not a readable cleaning grid: {e}") from None
    if visits.ndim != 2 or visits.shape != cleanable.shape:
        raise ReportError(
            f"{path}: visits {visits.shape} and cleanable {cleanable.shape} must be one 2-D shape"
        )
    if side is None:
        side = np.zeros(visits.shape, dtype=bool)
    if side.shape != visits.shape:
        raise ReportError(f"{path}: side {side.shape} and visits {visits.shape} must be one shape")
    if not resolution > 0 or origin.shape != (2,) or not width > 0:
        raise ReportError(f"{path}: resolution and cleaning_width_m must be > 0, origin x, y")
    return {
        "visits": visits.astype(np.int64),
        "side": side,
        "cleanable": cleanable,
        "resolution": resolution,
        "origin": (float(origin[0]), float(origin[1])),
        "cleaning_width_m": width,
    }


def read_csv(path: Path, columns: tuple[str, ...]) -> list[tuple[int, dict[str, str]]]:
    """The rows of a CSV file with ``columns`` as its header, each with its line number."""
    try:
        with path.open(newline="") as f:
            rows = list(csv.reader(f))
    except FileNotFoundError:
        raise ReportError(f"{path} does not exist: `fleet up` writes it when a run ends") from None
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise ReportError(f"cannot read {path}: {e}") from None
    if not rows or tuple(rows[0]) != columns:
        raise ReportError(f"{path}: line 1 must be the header {','.join(columns)}")
    out = []
    for line, row in enumerate(rows[1:], start=2):
        if len(row) != len(columns):
            raise ReportError(f"{path}:{line}: expected {len(columns)} fields, got {len(row)}")
        out.append((line, dict(zip(columns, row, strict=True))))
    return out


def _number(row: dict[str, str], key: str, path: Path, line: int) -> float:
    try:
        value = float(row[key])
    except ValueError:
        raise ReportError(f"{path}:{line}: field {key} is not a number: {row[key]!r}") from None
    if not np.isfinite(value):
        raise ReportError(f"{path}:{line}: field {key} is not finite: {row[key]!r}")
    return value
