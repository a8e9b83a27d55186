"""The exploration's picture (explore.png, explore.svg): the frontier goals read from the
coordinator's state with the robot each was last sold to, each robot's track and goals and the
growth curves named in the SVG, a goal not reached marked apart, and `fleet report` drawing an
exploration run dir again, or naming the file it misses."""

from __future__ import annotations

import json
import sqlite3
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from fleet.cli import app
from fleet.coordinator.exploring import MAP_YAML, write_ros_map
from fleet.coordinator.store import SCHEMA
from fleet.report.exploration import EXPLORE_REPORT
from fleet.report.explore_figure import FrontierGoal, frontier_goals, redraw_explore
from fleet.report.summary import TRACK_COLUMNS, TRACKS_FILE, ReportError
from planners.grid import GridMap

SVG = "{http://www.w3.org/2000/svg}"
runner = CliRunner()


def _state(path: Path) -> Path:
    """A coordinator state with two frontier tasks and a cleaning task: f001 sold to robot-0,
    then to robot-1, which reached it; f002 sold to robot-0 and gone before it got there."""
    db = sqlite3.connect(path)
    db.executescript(SCHEMA)
    for tid, goal, state in (("f001", (1.0, 1.5), "done"), ("f002", (3.0, 0.5), "gone")):
        path_blob = np.array([goal, (goal[0] + 0.3, goal[1])], dtype="<f8").tobytes()
        db.execute(
            "INSERT INTO tasks (id, path, state, kind) VALUES (?, ?, ?, 'frontier')",
            (tid, path_blob, state),
        )
    cleaning = np.zeros((2, 2), dtype="<f8").tobytes()
    db.execute(
        "INSERT INTO tasks (id, path, state, kind) VALUES ('t01', ?, 'done', 'tour')", (cleaning,)
    )
    for seq, (task, robot) in enumerate(
        (("f001", "robot-0"), ("f002", "robot-0"), ("f001", "robot-1")), start=1
    ):
        db.execute(
            "INSERT INTO events (seq, wall, sim, kind, robot, task, detail) "
            "VALUES (?, 0, ?, 'awarded', ?, ?, '')",
            (seq, float(seq), robot, task),
        )
    db.commit()
    db.close()
    return path


def _run_dir(tmp_path: Path) -> Path:
    """An exploration run dir as `fleet explore` writes it: explore.json, the merged map,
    tracks.csv and the coordinator's state."""
    d = tmp_path / "run"
    d.mkdir()
    occupied = np.zeros((40, 80), bool)
    occupied[[0, -1], :] = occupied[:, [0, -1]] = True
    unknown = np.zeros_like(occupied)
    unknown[:, 60:] = True
    write_ros_map(d, GridMap(occupied & ~unknown, unknown, 0.05, (0.0, 0.0)))
    rows = [
        f"{t:.1f},{rid},{x:.2f},{y:.2f}"
        for rid, y in (("robot-0", 0.5), ("robot-1", 1.5))
        for t, x in ((0.0, 0.5), (5.0, 1.5), (10.0, 2.5))
    ]
    (d / TRACKS_FILE).write_text(",".join(TRACK_COLUMNS) + "\n" + "\n".join(rows) + "\n")
    _state(d / "coordinator.sqlite")
    report = {
        "world": "box",
        "status": "done",
        "sim_s": 10.0,
        "known_m2": 6.0,
        "free_iou": 0.9,
        "walls_within": 0.95,
        "growth": [[1.0, 2.0, 3], [5.0, 4.5, 2], [10.0, 6.0, 0]],
    }
    (d / EXPLORE_REPORT).write_text(json.dumps(report))
    return d


def _ids(svg: Path) -> set[str]:
    return {el.get("id") for el in ET.parse(svg).getroot().iter() if el.get("id")}


def test_frontier_goals_are_the_frontier_tasks_with_their_last_award(tmp_path: Path) -> None:
    goals = frontier_goals(_state(tmp_path / "state.sqlite"))
    assert goals == [
        FrontierGoal("f001", "robot-1", 1.0, 1.5, "done"),
        FrontierGoal("f002", "robot-0", 3.0, 0.5, "gone"),
    ]


def test_the_picture_names_each_robots_track_and_goals_and_the_growth(tmp_path: Path) -> None:
    d = _run_dir(tmp_path)
    _, written = redraw_explore(d)
    assert written == [d / "explore.png", d / "explore.svg"]
    assert (d / "explore.png").stat().st_size > 0
    ids = _ids(d / "explore.svg")
    assert {"track-robot-0", "track-robot-1", "growth-known", "growth-frontiers"} <= ids
    # each robot's goals where it was sold one, and robot-1's last award of f001 wins
    assert {"goals-robot-0", "goals-robot-1"} <= ids
    root = ET.parse(d / "explore.svg").getroot()
    marks = {
        el.get("id"): len(list(el.iter(f"{SVG}path")))
        for el in root.iter()
        if el.get("id", "").startswith("goals-")
    }
    assert marks == {"goals-robot-0": 1, "goals-robot-1": 1}
    text = "".join(el.text or "" for el in root.iter(f"{SVG}text"))
    assert "free-space IoU 0.900" in text and "goal gone or unreachable" in text


def test_fleet_report_draws_an_exploration_run_again(tmp_path: Path) -> None:
    d = _run_dir(tmp_path)
    result = runner.invoke(app, ["report", str(d)])
    assert result.exit_code == 0, result.output
    assert "done: 6.0 m² known in 10 s sim, free-space IoU 0.900" in result.stdout
    assert f"wrote {d / 'explore.svg'}" in result.stdout
    assert (d / "explore.png").exists()


@pytest.mark.parametrize("missing", [MAP_YAML, TRACKS_FILE, "coordinator.sqlite"])
def test_a_missing_file_of_an_exploration_run_is_named(tmp_path: Path, missing: str) -> None:
    d = _run_dir(tmp_path)
    (d / missing).unlink()
    with pytest.raises(ReportError, match=missing):
        redraw_explore(d)
    result = runner.invoke(app, ["report", str(d)])
    assert result.exit_code == 2 and missing in result.stderr


def test_an_explore_json_without_its_growth_is_named(tmp_path: Path) -> None:
    d = _run_dir(tmp_path)
    report = json.loads((d / EXPLORE_REPORT).read_text())
    del report["growth"]
    (d / EXPLORE_REPORT).write_text(json.dumps(report))
    with pytest.raises(ReportError, match="missing field growth"):
        redraw_explore(d)
