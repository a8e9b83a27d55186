"""`fleet bench chaos` on a real fleet: one run with two faults (an agent killed and respawned,
then a rogue client), and the row it reports."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

WORLD = Path(__file__).resolve().parents[2] / "configs" / "worlds" / "small.yaml"


@pytest.mark.integration
@pytest.mark.slow
@pytest.mark.long
@pytest.mark.timeout(300)
def test_the_bench_makes_its_faults_and_the_job_survives_them(tmp_path: Path) -> None:
    # seed 3 draws robot-0 killed at 21 s sim and a rogue at 86 s of a 130 s job
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "fleet.cli",
            "bench",
            "chaos",
            "--runs",
            "1",
            "--faults",
            "2",
            "--seed",
            "3",
            "--world",
            str(WORLD),
            "--base-makespan",
            "130",
            "--run-root",
            str(tmp_path),
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=280,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout)
    assert result["no_fault"] is None and result["base_makespan_s"] == 130
    (row,) = result["runs"]
    assert [(f["kind"], f["target"]) for f in row["faults"]] == [
        ("kill-agent", "robot-0"),
        ("rogue", "rogue"),
    ]
    kill = row["faults"][0]
    assert kill["fired"] and 0 <= kill["detection_s"] < 5.0 and kill["rejoined"], kill
    assert row["rogue_sent"] > 100
    assert row["finished"] and row["tasks_lost"] == [], row
    assert row["crashed"] == [], row
    assert row["coverage"] >= 0.9
    # what the rogue sent was dropped and counted by the processes it was sent to
    dropped = row["dropped"]
    assert dropped["sim"]["implausible"] > 0 and dropped["coordinator"]["implausible"] > 0
    assert (tmp_path / "bench.json").exists()
