"""`fleet bench repetition` on a run dir built here: a one-robot run over an empty room whose
tour is two lanes joined by a hop back over the first lane's floor, driven exactly, swept by
the simulator's own brush, with the files `fleet up` writes."""

from __future__ import annotations

import csv
import json
import sqlite3
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from fleet.cli import app
from fleet.protocol import (
    TIME_KINDS,
)
from fleet.report.repetition import CAUSES, breakdown
from fleet.report.summary import STATUS_COLUMNS, ReportError
from planners.grid import GridMap
from planners.polyline import densify
from planners.tour_elements import tour_elements
from sim_server.cleaning import CleaningGrid

RES = 0.05
WIDTH = 0.30
SPEED = 0.25  # m/s along the track
STATUS_S = 0.5
LANE_A = np.array([[0.2, 0.3], [1.8, 0.3]])
# 5 cm beside lane A and back along it: a hop over floor lane A swept
HOP = np.array([[1.8, 0.3], [1.8, 0.35], [0.2, 0.35], [0.2, 0.6]])
LANE_B = np.array([[0.2, 0.6], [1.8, 0.6]])
TOUR = np.vstack([LANE_A, HOP[1:], LANE_B[1:]])


def _grid() -> GridMap:
    shape = (20, 40)  # 1 m x 2 m
    return GridMap(np.zeros(shape, bool), np.zeros(shape, bool), RES, (0.0, 0.0))


def _make_run(run_dir: Path, kinds_at: dict[tuple[float, float], str] | None = None) -> dict:
    """Write a run dir of one robot driving TOUR; ``kinds_at`` gives the step kind over arc
    length intervals (sweep elsewhere). Returns what the simulator counted."""
    run_dir.mkdir(parents=True)
    grid = _grid()
    cleanable = np.ones(grid.shape, dtype=bool)
    track = densify(TOUR, 0.0125)
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(track, axis=0).T))])
    times = 1.0 + arc / SPEED
    sim = CleaningGrid(grid, cleanable, WIDTH)
    for xy in track:
        sim.update(["robot-0"], xy[None, :])
    np.savez_compressed(
        run_dir / "coverage.npz",
        visits=sim.visits,
        cleanable=cleanable,
        resolution=RES,
        origin=np.array([0.0, 0.0]),
        cleaning_width_m=WIDTH,
    )
    _csv(
        run_dir / "tracks.csv",
        ("sim_s", "robot", "x", "y"),
        [(t, "robot-0", x, y) for t, (x, y) in zip(times, track, strict=True)],
    )
    _csv(run_dir / "coverage.csv", ("sim_s", "coverage", "repetition"), [])
    _csv(run_dir / "collisions.csv", ("sim_s", "kind", "robot", "other", "x", "y"), [])
    # statuses every STATUS_S: the waypoint of TOUR the robot heads for, seconds per kind
    stamps = np.arange(1.0, times[-1] + STATUS_S, STATUS_S)
    ends = np.cumsum(np.hypot(*np.diff(TOUR, axis=0).T))
    seconds = np.zeros(len(TIME_KINDS))
    rows = []
    for k, t in enumerate(stamps):
        s = (t - 1.0) * SPEED
        kind = "sweep"
        for (a, b), name in (kinds_at or {}).items():
            if a <= s - STATUS_S * SPEED / 2 <= b:
                kind = name
        if k:
            seconds[TIME_KINDS.index(kind)] += STATUS_S
        heading = min(int(np.searchsorted(ends, s, side="right")) + 1, len(TOUR) - 1)
        rows.append((t, "robot-0", 1, heading, *seconds))
    _csv(run_dir / "status.csv", STATUS_COLUMNS, rows)
    plan = {
        "sim_s": 1.0,
        "robot": "robot-0",
        "plan_id": 1,
        "task": "t00",
        "sweep_from": 0,
        "chain": ["t00"],
        "chain_starts": [0],
        "waypoints": TOUR.tolist(),
    }
    (run_dir / "plans.jsonl").write_text(json.dumps(plan) + "\n")
    elements = tour_elements(TOUR, [[LANE_A], [LANE_B]], [0.0, 0.0])
    db = sqlite3.connect(run_dir / "coordinator.sqlite")
    db.execute("CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT)")
    db.execute("CREATE TABLE tasks (id TEXT PRIMARY KEY, parent TEXT, path BLOB, kind TEXT)")
    tour = {"resolution_m": 0.025, "lane_overlap": 0.1, "repetition": 0.0}
    db.executemany(
        "INSERT INTO meta VALUES (?, ?)",
        [("tour_elements", json.dumps(elements.to_json())), ("tour", json.dumps(tour))],
    )
    db.execute("INSERT INTO tasks VALUES ('t00', NULL, ?, 'tour')", (TOUR.astype("<f8").tobytes(),))
    db.commit()
    db.close()
    report = {
        "format": 2,
        "status": "done",
        "coverage": sim.coverage(),
        "repetition": sim.repetition(),
        "sim_time_s": float(times[-1]),
        "wall_s": 1.0,
        "cleanable_m2": sim.cleanable_m2,
        "collisions": {"robot_wall": 0, "robot_robot": 0},
        "robots": {"robot-0": {}},
        "world": "room.yaml",
        "seed": 0,
    }
    (run_dir / "report.json").write_text(json.dumps(report))
    return {"repetition": sim.repetition(), "swept": int(np.count_nonzero(sim.visits))}


def _csv(path: Path, header: tuple[str, ...], rows: list[tuple]) -> None:
    with path.open("w", newline="") as f:
        out = csv.writer(f)
        out.writerow(header)
        out.writerows(rows)


def _hop_re_entries() -> int:
    """Re-entries while driving the hop, counted by the simulator's brush alone: what lane A
    and the hop's own start had swept before, entered again."""
    brush = CleaningGrid(_grid(), np.ones((20, 40), dtype=bool), WIDTH)
    for xy in densify(LANE_A, 0.0125):
        brush.update(["r"], xy[None, :])
    visits, swept = brush.repetition(), brush.coverage()
    before = (visits + 1) * swept
    for xy in densify(HOP, 0.0125)[1:]:
        brush.update(["r"], xy[None, :])
    after = (brush.repetition() + 1) * brush.coverage()
    new_cells = (brush.coverage() - swept) * 800
    return round((after - before) * 800 - new_cells)


def test_the_causes_sum_to_the_runs_repetition(tmp_path: Path) -> None:
    sim = _make_run(tmp_path / "run", {(3.6, 4.6): "escape", (4.8, 5.2): "turn"})
    r = breakdown(tmp_path / "run")
    assert set(r["causes"]) == set(CAUSES)
    assert r["replay_repetition"] == pytest.approx(100 * sim["repetition"], abs=1e-3)
    assert sum(r["causes"].values()) == pytest.approx(100 * sim["repetition"], abs=0.01)
    assert sum(r["kinds"].values()) == pytest.approx(100 * sim["repetition"], abs=0.01)
    assert sum(r["elements"].values()) == pytest.approx(100 * sim["repetition"], abs=0.01)
    assert r["causes"]["escape"] > 0 and r["cells_as_simulated"] == 1.0
    # the tour alone is the same path: the same repetition, and no step kinds
    assert r["tour"]["repetition"] == pytest.approx(100 * sim["repetition"], abs=1e-3)
    assert r["tour"]["causes"]["escape"] == 0


def test_a_hop_driven_over_swept_floor_is_charged_to_hops_not_lanes(tmp_path: Path) -> None:
    sim = _make_run(tmp_path / "run")
    r = breakdown(tmp_path / "run")
    hop = 100 * _hop_re_entries() / sim["swept"]
    assert hop > 5.0, "the hop re-enters most of lane A's swath"
    for part in (r["causes"], r["tour"]["causes"]):
        assert part["hop_long"] == pytest.approx(hop, abs=1e-3)
        # the rest is lane B's: beside the hop, and over lane A's and the hop's floor
        rest = sum(v for c, v in part.items() if c != "hop_long")
        assert rest == pytest.approx(100 * sim["repetition"] - hop, abs=0.01)
        assert part["hop_side_by_side"] > 0 and part["lane_over_hop"] > 0


def test_a_run_dir_without_the_status_file_names_it_and_the_format(tmp_path: Path) -> None:
    _make_run(tmp_path / "run")
    (tmp_path / "run" / "status.csv").unlink()
    with pytest.raises(ReportError, match=r"status\.csv does not exist.*report format 2"):
        breakdown(tmp_path / "run")
    res = CliRunner().invoke(app, ["bench", "repetition", str(tmp_path / "run")])
    assert res.exit_code == 2 and "status.csv" in res.output


def test_the_command_prints_a_table_per_world(tmp_path: Path) -> None:
    _make_run(tmp_path / "runs" / "room-seed0")
    res = CliRunner().invoke(app, ["bench", "repetition", str(tmp_path / "runs")])
    assert res.exit_code == 0, res.output
    assert "| hops > 1 m |" in res.output and "the tour alone" in res.output
