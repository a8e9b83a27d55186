"""The generated family's per-mode summary and verdict (fleet.bench.family_verdict), on made-up
run figures: each of issue 30's targets fails the verdict alone."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from fleet.bench.family_verdict import family_run, family_summary, mode_summary

ROOT = Path(__file__).resolve().parents[2]


def _figures(
    member: str,
    mode: str,
    seed: int = 0,
    makespan: float | None = 200.0,
    status: str = "done",
    coverage: float = 0.97,
    robot_contacts: int = 0,
    unreachable: tuple[str, ...] = (),
) -> dict[str, Any]:
    """What fleet.bench.fleet.run_figures gives for a run of the family."""
    return {
        "world": f"{member}/{mode}",
        "seed": seed,
        "status": status,
        "coverage": coverage,
        "makespan_s": makespan,
        "contacts": {"robot_wall": 1, "robot_robot": robot_contacts},
        "skipped_waypoints": 2,
        "unreachable": list(unreachable),
    }


def _runs(**prioritized: Any) -> list[dict[str, Any]]:
    """local and prioritized on two members; prioritized's second run changed by the keywords."""
    figures = [
        _figures("c0.45x2.5", "local", makespan=200.0),
        _figures("L0.6", "local", makespan=300.0),
        _figures("c0.45x2.5", "prioritized", makespan=190.0),
        _figures("L0.6", "prioritized", **{"makespan": 290.0, **prioritized}),
    ]
    return [family_run(f) for f in figures]


def test_a_run_is_split_into_member_and_mode() -> None:
    run = family_run(_figures("3rooms0.6", "cbs", seed=2, unreachable=("robot-1 t3: far",)))
    assert (run["member"], run["mode"], run["seed"]) == ("3rooms0.6", "cbs", 2)
    assert run["unreachable"] == ["robot-1 t3: far"] and run["given_up"] == 2
    lost = family_run({"world": "door0.8/local", "seed": 1, "status": "no report"})
    assert lost["coverage"] is None and lost["unreachable"] is None


def test_a_mode_that_meets_every_target_passes_and_local_has_no_makespan_check() -> None:
    summary = family_summary(_runs())
    assert list(summary) == ["local", "prioritized"]
    assert summary["prioritized"]["verdict"] == "PASS"
    assert summary["prioritized"]["makespan_over_local_median"] == pytest.approx(0.9583, abs=1e-3)
    assert summary["prioritized"]["wall_contacts"] == 2
    assert summary["local"]["checks"]["makespan ≤ local"] is None
    assert summary["local"]["verdict"] == "PASS"


@pytest.mark.parametrize(
    ("change", "check"),
    [
        ({"unreachable": ("robot-2 t7: its goal cannot be reached",)}, "no unreachable"),
        ({"coverage": 0.949}, "all done, coverage ≥ 0.95"),
        ({"status": "timeout", "makespan": None}, "all done, coverage ≥ 0.95"),
        ({"robot_contacts": 1}, "no robot contact"),
        ({"makespan": 340.0}, "makespan ≤ local"),
    ],
)
def test_each_target_missed_alone_fails_the_mode(change: dict[str, Any], check: str) -> None:
    summary = mode_summary(_runs(**change), "prioritized")
    assert summary["verdict"] == "FAIL"
    assert [c for c, ok in summary["checks"].items() if ok is False] == [check]


def test_a_run_without_a_report_fails_the_finishing_target() -> None:
    runs = _runs()
    runs[3] = family_run({"world": "L0.6/prioritized", "seed": 0, "status": "no report"})
    summary = mode_summary(runs, "prioritized")
    assert summary["finished"] == 1 and summary["runs"] == 2
    assert summary["checks"]["all done, coverage ≥ 0.95"] is False
    assert summary["checks"]["makespan ≤ local"] is True  # the one pair both finished


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--family-members", "c9x9"], "--family-members"),
        (["--modes", "fast"], "--modes"),
        (["--family-seeds", "0-x"], "--seeds"),
    ],
)
def test_the_family_bench_refuses_bad_arguments_before_any_run(
    args: list[str], message: str, tmp_path: Path
) -> None:
    out = subprocess.run(
        [sys.executable, "-m", "fleet.cli", "bench", "deconfliction", "--family", *args],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert out.returncode != 0 and message in out.stderr, out.stderr
    assert not list(tmp_path.iterdir())
