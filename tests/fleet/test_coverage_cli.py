"""fleet plan coverage: outputs, JSON keys, and clear errors for bad maps and starts."""

import json

import numpy as np
from coverage_maps import write_ros_map
from typer.testing import CliRunner

from fleet.cli import app

runner = CliRunner()

KEYS = {"coverage", "repetition", "path_length_m", "turns", "est_time_s", "makespan_s"}


def _plan(*args):
    return runner.invoke(app, ["plan", "coverage", *map(str, args)])


def _room_pixels(rows=60, cols=90):
    px = np.full((rows, cols), 254, dtype=np.uint8)
    px[0, :] = px[-1, :] = px[:, 0] = px[:, -1] = 0
    return px


def test_writes_paths_json_and_plan_png_and_prints_metrics(tmp_path):
    res = _plan("small", "--robots", "2", "--out", tmp_path, "--json")
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout)
    assert KEYS | {"plan_time_s"} <= set(summary)
    assert 0.9 < summary["coverage"] <= 1.0
    doc = json.loads((tmp_path / "paths.json").read_text())
    assert doc["frame"] == "world" and len(doc["robots"]) == 2
    assert doc["cleaning_width_m"] == 0.30 and doc["robot_radius_m"] == 0.17
    for i, robot in enumerate(doc["robots"]):
        assert robot["id"] == i and np.array(robot["path"]).shape[1] == 2
        assert np.allclose(robot["path"][0], robot["start"])
    assert (tmp_path / "plan.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_table_names_the_unreachable_free_space(tmp_path):
    px = _room_pixels()
    px[:, 45] = 0  # the right half has no door
    ros = write_ros_map(tmp_path, px)
    res = _plan(ros, "--start", "1.0,1.5", "--out", tmp_path / "out")
    assert res.exit_code == 0, res.output
    assert "unreachable free space" in res.output
    line = next(x for x in res.output.splitlines() if "unreachable free space" in x)
    assert float(line.split(":")[1].split("m²")[0]) > 2.0  # the right half: 2.2 m × 2.9 m


def test_missing_image_names_the_file(tmp_path):
    ros = write_ros_map(tmp_path, _room_pixels(), image="nowhere.pgm")
    res = _plan(ros, "--out", tmp_path / "out")
    assert res.exit_code == 2
    assert "map.yaml" in res.output and "nowhere.pgm" in res.output


def test_bad_thresholds_name_the_field(tmp_path):
    ros = write_ros_map(tmp_path, _room_pixels(), occupied_thresh=0.1, free_thresh=0.5)
    res = _plan(ros, "--out", tmp_path / "out")
    assert res.exit_code == 2
    assert "map.yaml" in res.output and "thresh" in res.output


def test_no_free_space_is_an_error(tmp_path):
    ros = write_ros_map(tmp_path, np.zeros((20, 20), dtype=np.uint8))
    res = _plan(ros, "--start", "0.5,0.5", "--out", tmp_path / "out")
    assert res.exit_code == 2
    assert "map.yaml" in res.output and "no free cell" in res.output


def test_start_inside_an_obstacle_is_an_error(tmp_path):
    ros = write_ros_map(tmp_path, _room_pixels())
    res = _plan(ros, "--start", "0.02,1.0", "--out", tmp_path / "out")
    assert res.exit_code == 2
    assert "map.yaml" in res.output and "inside an obstacle" in res.output
    res = _plan(ros, "--start", "1.0;1.0", "--out", tmp_path / "out")
    assert res.exit_code == 2 and "X,Y" in res.output


def test_starts_must_match_robots(tmp_path):
    res = _plan("small", "--robots", "3", "--start", "0.6,0.85", "--out", tmp_path)
    assert res.exit_code == 2 and "one start per robot" in res.output


def test_a_lower_coverage_target_gives_a_shorter_path(tmp_path):
    full = json.loads(_plan("small", "--out", tmp_path / "a", "--json").stdout)
    res = _plan("small", "--coverage-target", "0.95", "--out", tmp_path / "b", "--json")
    assert res.exit_code == 0, res.output
    less = json.loads(res.stdout)
    assert 0.95 <= less["coverage"] < full["coverage"]
    assert less["path_length_m"] < full["path_length_m"]
    res = _plan("small", "--coverage-target", "1.5", "--out", tmp_path / "c")
    assert res.exit_code == 2 and "coverage-target" in res.output


def test_plans_the_tour_the_coordinator_cuts_into_tasks(tmp_path):
    from fleet.config import resolve_world
    from fleet.coordinator.planning import TaskPlanner
    from fleet.params import load_fleet_config
    from fleet.world import load_world

    res = _plan("small", "--out", tmp_path, "--json")
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout)
    path = np.array(json.loads((tmp_path / "paths.json").read_text())["robots"][0]["path"])
    cfg = load_fleet_config()
    planner = TaskPlanner(load_world(resolve_world("small"), cfg.robot.radius), cfg)
    tasks = planner.tasks()
    tour = np.vstack([tasks[0].path] + [t.path[1:] for t in tasks[1:]])
    assert path.shape == tour.shape and np.allclose(path, tour, atol=1e-4)
    figures = planner.meta["tour"]
    for key in ("coverage", "repetition", "path_length_m", "turns"):
        assert summary[key] == figures[key]
    assert summary["plan"] == {
        "resolution_m": 0.025,
        "lane_overlap": cfg.coordinator.lane_overlap,
        "wall_clearance_m": cfg.coordinator.wall_clearance,
        "bare": False,
    }


def test_bare_plans_as_the_planner_alone(tmp_path):
    res = _plan("small", "--bare", "--out", tmp_path, "--json")
    assert res.exit_code == 0, res.output
    plan = json.loads(res.stdout)["plan"]
    assert plan == {
        "resolution_m": 0.05,
        "lane_overlap": 0.0,
        "wall_clearance_m": 0.0,
        "bare": True,
    }
