"""``fleet plan mapf`` and ``fleet bench mapf`` end to end through the typer app."""

from __future__ import annotations

import json
from pathlib import Path

import yaml
from typer.testing import CliRunner

from fleet.bench.mapf import user_suite
from fleet.cli import app
from planners.mapf import MapfInstance, validate
from planners.mapf.generate import random_instance, random_map
from planners.mapf.movingai import write_map, write_scen
from planners.mapf.yaml_format import instance_to_mapping, schedule_from_mapping, write_yaml

runner = CliRunner()


def _files(tmp_path: Path) -> tuple[Path, Path, MapfInstance]:
    free = random_map(16, 16, 0.1, 7)
    instance = random_instance(free, 12, 3)
    write_map(tmp_path / "r.map", free)
    write_scen(tmp_path / "r.scen", "r.map", instance)
    return tmp_path / "r.map", tmp_path / "r.scen", instance


def test_plan_json_and_schedule(tmp_path: Path) -> None:
    map_path, scen_path, instance = _files(tmp_path)
    out = tmp_path / "schedule.yaml"
    args = ["plan", "mapf", str(map_path), str(scen_path), "--agents", "8", "--solver", "cbs"]
    result = runner.invoke(app, [*args, "--json", "--out", str(out)])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert {"status", "soc", "makespan", "runtime_s", "expanded"} <= set(summary)
    assert summary["status"] == "success"
    assert summary["valid"] is True
    data = yaml.safe_load(out.read_text())
    assert data["statistics"]["cost"] == summary["soc"]
    first8 = instance.first(8)
    assert validate(first8, schedule_from_mapping(first8, data)).soc == summary["soc"]


def test_plan_yaml_instance_with_every_solver(tmp_path: Path) -> None:
    _, _, instance = _files(tmp_path)
    write_yaml(tmp_path / "in.yaml", instance_to_mapping(instance))
    socs = {}
    for solver in ("pp", "sipp-pp", "cbs", "ecbs"):
        result = runner.invoke(
            app, ["plan", "mapf", str(tmp_path / "in.yaml"), "--solver", solver, "--json"]
        )
        assert result.exit_code == 0, result.output
        summary = json.loads(result.stdout)
        assert summary["status"] == "success" and summary["valid"]
        socs[solver] = summary["soc"]
    assert socs["cbs"] <= min(socs.values())
    assert socs["ecbs"] <= 1.2 * socs["cbs"]


def test_plan_table_output(tmp_path: Path) -> None:
    map_path, scen_path, _ = _files(tmp_path)
    result = runner.invoke(app, ["plan", "mapf", str(map_path), str(scen_path), "-k", "3"])
    assert result.exit_code == 0, result.output
    assert "success" in result.stdout and "makespan" in result.stdout


def test_plan_rejects_infeasible_and_bad_input(tmp_path: Path) -> None:
    (tmp_path / "in.yaml").write_text(
        "map: {dimensions: [3, 1], obstacles: [[1, 0]]}\n"
        "agents: [{name: a, start: [0, 0], goal: [2, 0]}]\n"
    )
    result = runner.invoke(app, ["plan", "mapf", str(tmp_path / "in.yaml"), "--json"])
    assert result.exit_code == 5
    summary = json.loads(result.stdout)
    assert summary["status"] == "infeasible"
    assert "unreachable" in summary["message"]
    result = runner.invoke(app, ["plan", "mapf", str(tmp_path / "in.yaml"), "--solver", "dijkstra"])
    assert result.exit_code == 2
    assert "--solver must be one of" in result.output
    map_path, _, _ = _files(tmp_path)
    result = runner.invoke(app, ["plan", "mapf", str(map_path)])
    assert result.exit_code == 2
    assert "give a .scen" in result.output


def test_bench_smoke(tmp_path: Path) -> None:
    args = [
        "bench",
        "mapf",
        "--json",
        "--map",
        "gen-random-10pct",
        "--solver",
        "pp",
        "--solver",
        "cbs",
        "--k-step",
        "5",
        "--k-max",
        "10",
        "--time-limit",
        "5",
        "--keep",
        str(tmp_path),
    ]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    rows = {row["solver"]: row for row in report["summary"]}
    assert rows["pp"]["max_k"] == rows["cbs"]["max_k"] == 10
    assert rows["cbs"]["all_valid"] is True
    assert (tmp_path / "gen-random-10pct.map").exists()
    assert (tmp_path / "gen-random-10pct-0.scen").exists()


def test_plan_without_a_solution_exits_non_zero_and_suggests_cbs(tmp_path: Path) -> None:
    # a swap through a side pocket: PP fails in both orders, CBS solves it
    (tmp_path / "pocket.yaml").write_text(
        "map: {dimensions: [5, 2], obstacles: [[0, 1], [1, 1], [3, 1], [4, 1]]}\n"
        "agents: [{name: a, start: [0, 0], goal: [4, 0]}, {name: b, start: [4, 0], goal: [0, 0]}]\n"
    )
    path = str(tmp_path / "pocket.yaml")
    for solver in ("pp", "sipp-pp"):
        result = runner.invoke(app, ["plan", "mapf", path, "--solver", solver, "--json"])
        assert result.exit_code == 1, result.output
        assert json.loads(result.stdout)["status"] == "failed"
        assert "--solver cbs" in result.stderr
    result = runner.invoke(app, ["plan", "mapf", path, "--solver", "cbs", "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["soc"] == 11


def test_plan_timeout_exits_non_zero(tmp_path: Path) -> None:
    map_path, scen_path, _ = _files(tmp_path)
    args = ["plan", "mapf", str(map_path), str(scen_path), "--time-limit", "0", "--json"]
    result = runner.invoke(app, args)
    assert result.exit_code == 4, result.output
    assert json.loads(result.stdout)["status"] == "timeout"
    assert "--time-limit" in result.stderr


def test_bench_tiny_checks_solvers_against_the_brute_force() -> None:
    # the check is of correctness, not speed: a limit no starved machine reaches (the tiny
    # bench's default of 1 s a case timed one out under a CPU hog)
    args = ["bench", "mapf", "--tiny", "15", "--seed", "2", "--json", "--time-limit", "60"]
    result = runner.invoke(app, [*args, "--solver", "cbs", "--solver", "ecbs", "--solver", "pp"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["config"]["instances"] == 15
    assert report["config"]["w"] == 1.5
    rows = {row["solver"]: row for row in report["summary"]}
    assert set(rows) == {"cbs", "ecbs", "pp"}
    for solver in ("cbs", "ecbs"):
        assert rows[solver]["solved"] == rows[solver]["correct"] == 1.0
        assert rows[solver]["p50_s"] <= rows[solver]["p99_s"] <= rows[solver]["max_s"]
        assert "MapfInstance(np.array(" in rows[solver]["slowest"]["instance"]
    result = runner.invoke(app, ["bench", "mapf", "--tiny", "3", "--solver", "cbs"])
    assert result.exit_code == 0, result.output
    assert "slowest for cbs" in result.stdout


def test_help_documents_each_exit_status() -> None:
    result = runner.invoke(app, ["plan", "mapf", "--help"], env={"COLUMNS": "5000"})
    assert result.exit_code == 0
    for status in ("0 solved", "1 prioritized planning failed", "2 bad input", "3 invalid"):
        assert status in result.output
    assert "4 timeout" in result.output and "5 infeasible" in result.output


def test_bench_runs_a_users_movingai_map_on_the_scenarios_beside_it(tmp_path: Path) -> None:
    free = random_map(16, 16, 0.1, 7)
    write_map(tmp_path / "mine.map", free)
    for i in (1, 2, 10):
        write_scen(tmp_path / f"mine-random-{i}.scen", "mine.map", random_instance(free, 6, i))
    files = user_suite([tmp_path / "mine.map"], 2)
    assert files == {
        "mine": (tmp_path / "mine.map", [tmp_path / f"mine-random-{i}.scen" for i in (1, 2)])
    }
    args = ["bench", "mapf", "--json", "--map", str(tmp_path / "mine.map"), "--solver", "cbs"]
    result = runner.invoke(app, [*args, "--k-step", "3", "--k-max", "6", "--scenarios", "2"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert [(r["map"], r["max_k"]) for r in report["summary"]] == [("mine", 6)]
    assert {run["scenario"] for run in report["runs"]} == {0, 1}
    (tmp_path / "lone.map").write_text((tmp_path / "mine.map").read_text())
    for bad, why in (("lone.map", "no lone-*.scen"), ("random-32-32-10", "a MovingAI .map file")):
        result = runner.invoke(app, ["bench", "mapf", "--map", str(tmp_path / bad)])
        assert result.exit_code == 2 and why in result.output, result.output
