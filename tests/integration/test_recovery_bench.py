"""`fleet bench recovery` on a real fleet (one SIGKILL and one SIGSTOP trial), and its
summary figures."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from fleet.bench.recovery import summarize

WORLD = Path(__file__).resolve().parents[2] / "configs" / "worlds" / "small.yaml"


def test_the_summary_takes_medians_and_p95_per_signal() -> None:
    trials = [
        {"signal": "KILL", "detection_s": d, "reassignment_s": 0.02, "rejoined": True}
        for d in (0.01, 0.02, 0.03)
    ] + [{"signal": "STOP", "detection_s": 1.0, "reassignment_s": None, "rejoined": False}]
    out = summarize(trials)
    assert out["detection_kill_s"]["median"] == 0.02
    assert out["detection_kill_s"]["n"] == 3
    assert out["detection_stop_s"]["max"] == 1.0
    assert out["reassignment_s"]["n"] == 3
    assert out["rejoined"] == 3 and out["trials"] == 4
    assert summarize([])["detection_kill_s"]["median"] is None


@pytest.mark.integration
@pytest.mark.long
@pytest.mark.timeout(300)
def test_the_bench_measures_a_kill_and_a_hang_on_a_real_fleet(tmp_path: Path) -> None:
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "fleet.cli",
            "bench",
            "recovery",
            "--world",
            str(WORLD),
            "--kills",
            "1",
            "--no-scenarios",
            "--run-root",
            str(tmp_path),
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=280,
    )
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    kinds = [t["signal"] for t in result["trials"]]
    assert kinds == ["KILL", "STOP"], done.stderr
    for t in result["trials"]:
        assert 0 <= t["detection_s"] < 5.0
        assert t["rejoined"] and t["all_reassigned"], t
    # a hang is noticed by its silence: the heartbeat timeout (1 s) after the last heartbeat,
    # which is at most one heartbeat period (0.2 s) before the signal
    assert result["trials"][1]["detection_s"] >= 0.75
    assert result["auction_ms_per_lot"]["n"] >= 1
    assert (tmp_path / "bench.json").exists()
    # the runs end without a report: robot-robot contacts are in the simulator's log
    logs = sorted(tmp_path.glob("latency-*/sim.log"))
    assert logs
    lines = [ln for log in logs for ln in log.read_text().splitlines()]
    contacts = [ln for ln in lines if "collision robot" in ln]
    assert contacts == [], "\n".join(contacts)
