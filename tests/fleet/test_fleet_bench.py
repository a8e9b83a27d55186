"""`fleet bench fleet`'s figures from reports, and its command line's checks."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fleet.bench.fleet import run_figures, world_summary
from fleet.coordinator.market import PEER_HELD
from fleet.protocol import TIME_KINDS


def _report(makespan: float | None, wall_contacts: int, skipped: list[int | None]) -> dict:
    robots = {
        f"robot-{i}": {
            "skipped_waypoints": s,
            "time_s": {k: 10.0 * (i + 1) if k == "sweep" else 1.0 for k in TIME_KINDS},
        }
        for i, s in enumerate(skipped)
    }
    return {
        "status": "done" if makespan else "timeout",
        "coverage": 0.97,
        "repetition": 0.3,
        "makespan_s": makespan,
        "plan_estimate_s": 100.0,
        "sim_time_s": 200.0,
        "wall_s": 50.0,
        "collisions": {"robot_wall": wall_contacts, "robot_robot": 0},
        "robots": robots,
    }


def test_one_runs_figures_come_from_its_report() -> None:
    r = run_figures(_report(150.0, 1, [2, None, 1]), "home", 3)
    assert r["makespan_over_estimate"] == 1.5 and r["real_time_factor"] == 4.0
    assert r["skipped_waypoints"] == 3  # an agent that never reported counts as unknown, not 0
    assert r["time_s"]["sweep"] == 60.0 and r["time_s"]["turn"] == 3.0
    assert run_figures(None, "home", 4) == {"world": "home", "seed": 4, "status": "no report"}


def test_a_runs_unreachable_events_are_kept_with_robot_task_and_why() -> None:
    report = _report(150.0, 0, [0])
    event = {"sim": 12.0, "robot": "robot-1", "task": "t4", "detail": "its goal cannot be reached"}
    report["events"] = [
        {**event, "kind": "awarded", "detail": ""},
        {**event, "kind": "unreachable"},
    ]
    assert run_figures(report, "c0.45x2.5/prioritized", 0)["unreachable"] == [
        "robot-1 t4: its goal cannot be reached"
    ]
    assert run_figures(_report(150.0, 0, [0]), "home", 0)["unreachable"] == []


def test_stuck_events_are_counted_and_those_a_peer_caused_apart() -> None:
    report = _report(150.0, 0, [0])
    report["events"] = [
        {"kind": "stuck", "robot": "robot-1", "task": "", "detail": "no progress for 30 s"},
        {"kind": "stuck", "robot": "robot-2", "task": "", "detail": f"…; {PEER_HELD}, so …"},
        {"kind": "done", "robot": "robot-2", "task": "t01", "detail": ""},
    ]
    r = run_figures(report, "home", 0)
    assert (r["stuck"], r["stuck_by_peer"]) == (2, 1)
    s = world_summary([r, run_figures(_report(150.0, 0, [0]), "home", 1)])
    assert (s["stuck_total"], s["stuck_by_peer_total"]) == (2, 1)


def test_a_worlds_medians_skip_runs_without_a_report_and_contacts_are_summed() -> None:
    runs = [
        run_figures(_report(150.0, 1, [0, 0]), "home", 0),
        run_figures(_report(None, 0, [2, 0]), "home", 1),
        run_figures(_report(130.0, 2, [0, 0]), "home", 2),
        run_figures(None, "home", 3),
    ]
    s = world_summary(runs)
    assert s["runs"] == 4 and s["finished"] == 2
    assert s["makespan_s"] == 140.0  # the timed-out run has no makespan
    assert s["contacts_total"] == 3 and s["contacts_worst_run"] == 2
    assert s["skipped_total"] == 2
    assert s["time_s_median"]["sweep"] == 30.0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--worlds", "nowhere"], "--worlds"),
        (["--seeds", "0-x"], "--seeds"),
        (["--speed", "-1"], "--speed"),
        (["--robots", "0"], "--robots"),
    ],
)
def test_bad_arguments_are_refused_before_any_run(args: list[str], message: str) -> None:
    out = subprocess.run(
        [sys.executable, "-m", "fleet.cli", "bench", "fleet", *args],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode != 0 and message in out.stderr, out.stderr


def test_a_bad_config_is_refused_naming_its_field_before_any_run(tmp_path: Path) -> None:
    from fleet.params import default_config_path

    bad = tmp_path / "fleet.yaml"
    text = default_config_path().read_text()
    bad.write_text(text.replace("  lane_overlap: ", "  lane_overlapp: ", 1))
    args = ["--worlds", "small", "--config", str(bad), "--run-root", str(tmp_path / "runs")]
    out = subprocess.run(
        [sys.executable, "-m", "fleet.cli", "bench", "fleet", *args],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode != 0, out.stderr
    assert "--config" in out.stderr and "coordinator.lane_overlapp" in out.stderr, out.stderr
    assert not (tmp_path / "runs").exists()


def test_every_run_is_handed_the_config(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import fleet.bench.fleet as bench
    import fleet.cli.fleet_bench as cli
    from fleet.params import default_config_path

    handed: list = []
    monkeypatch.setattr(bench, "run_bench", lambda _root, scenarios, *_a: handed.extend(scenarios))
    monkeypatch.setattr(cli, "print_result", lambda *_a: None)
    mine = tmp_path / "mine.yaml"
    mine.write_text(default_config_path().read_text())
    cli.bench_fleet(worlds="small,home", seeds="0", run_root=tmp_path / "runs", config=mine)
    assert [s.name for s in handed] == ["small", "home"]
    assert all(s.options == ("--config", str(mine.resolve())) for s in handed)


def test_one_robot_drives_the_small_worlds_whole_tour_in_process(tmp_path: Path) -> None:
    from agents.follow.state import FollowParams
    from fleet.bench.follow import follow_tour
    from fleet.carmen import read_log
    from fleet.config import resolve_world
    from fleet.params import load_fleet_config
    from fleet.world import load_world

    cfg = load_fleet_config()
    world = load_world(resolve_world("small"), cfg.robot.radius)
    log = tmp_path / "tour.log"
    r = follow_tour(world, cfg, seed=0, pose_source="truth", record=log)
    assert r["finished"] and r["contacts"] == 0
    assert r["coverage"] > 0.95 and 0.0 < r["repetition"] < 0.6
    # every control step is put somewhere, and the run took longer than the plan's estimate
    assert sum(r["time_s"].values()) == pytest.approx(r["sim_s"], abs=0.5)
    assert r["time_s"]["sweep"] > 0.5 * r["plan_estimate_s"] and r["time_over_estimate"] > 1.0
    assert 0 < r["tracking_m"]["mean"] < r["tracking_m"]["p95"] <= r["tracking_m"]["max"]
    # the cross-track error is measured on lanes only, a good part of the sweep (lanes are
    # driven at full speed, hops and U-turns slower), and never exceeds the distance to the
    # segment
    lane = r["lane_cross_track_m"]
    assert lane["steps"] > 0.25 * r["time_s"]["sweep"] / FollowParams.of(cfg).dt
    assert 0 < lane["mean"] < lane["p95"] <= lane["max"] <= r["tracking_m"]["max"]
    assert len(r["given_up_points"]) == r["given_up"]
    # the recording holds every scan the follower answered, the true pose beside each
    scans = read_log(log).front_scans
    steps = sum(r["time_s"].values()) / FollowParams.of(cfg).dt
    assert abs(len(scans) - steps) <= 2
    truth = np.loadtxt(f"{log}.truth.csv", delimiter=",", skiprows=1)
    assert len(truth) == len(scans)
    assert np.allclose(truth[:, 0], [s.timestamp for s in scans], atol=1e-6)


def test_the_missed_floor_is_split_by_clearance_in_the_report_and_the_bench() -> None:
    from fleet.config import resolve_world
    from fleet.protocol import CoverageImage
    from fleet.report.summary import MISSED_BANDS, missed_breakdown
    from fleet.world import load_world

    grid = load_world(resolve_world("small")).grid(0.05)
    visits = np.ones(grid.shape, dtype=np.uint16)
    visits[:, : grid.shape[1] // 2] = 0  # the left half never cleaned
    cleanable = grid.free.astype(np.uint8)
    image = CoverageImage(
        0.0, 0.05, *grid.origin, *grid.shape, visits.reshape(-1), cleanable.reshape(-1)
    )
    missed = missed_breakdown(image, grid)
    assert missed is not None and list(missed) == list(MISSED_BANDS)
    assert sum(missed.values()) == pytest.approx(
        (cleanable.astype(bool) & (visits == 0)).sum() / cleanable.sum(), abs=1e-4
    )
    assert all(v > 0 for v in missed.values())
    assert missed_breakdown(image, load_world(resolve_world("small")).grid(0.1)) is None
    report = _report(150.0, 0, [0]) | {"missed": missed}
    runs = [run_figures(report, "small", 0), run_figures(report, "small", 1)]
    assert runs[0]["missed"] == missed
    assert world_summary(runs)["missed_median"] == pytest.approx(missed, abs=1e-4)
