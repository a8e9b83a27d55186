"""`fleet bench soak` on a real fleet, briefly: two robots on the small world looping its job
for 90 sim seconds, sampled every 30; the samples and the verdict it reports."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

WORLD = Path(__file__).resolve().parents[2] / "configs" / "worlds" / "small.yaml"
PROCESSES = {"up", "router", "sim", "coordinator", "robot-0", "robot-1"}


@pytest.mark.integration
@pytest.mark.slow
@pytest.mark.long
@pytest.mark.timeout(300)
def test_the_soak_samples_every_process_and_judges_them(tmp_path: Path) -> None:
    run_dir = tmp_path / "soak"
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "fleet.cli",
            "bench",
            "soak",
            "--robots",
            "2",
            "--world",
            str(WORLD),
            "--sim-s",
            "90",
            "--every",
            "30",
            "--warmup-s",
            "30",
            "--run-dir",
            str(run_dir),
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=280,
    )
    # exit 1 is a failed verdict: a run this short is no judge of memory growth
    assert done.returncode in (0, 1), done.stderr[-3000:]
    result = json.loads(done.stdout)
    assert result == json.loads((run_dir / "soak.json").read_text())
    assert result["stopped"] == "" and result["left_processes"] == [], result
    samples = result["samples"]
    assert [round(s["sim_s"] / 30) for s in samples] == [1, 2, 3]
    assert all(set(s["rss_kb"]) == PROCESSES for s in samples)
    assert all(v > 10_000 for s in samples for v in s["rss_kb"].values())
    assert all(v >= 3 for s in samples for v in s["fds"].values())
    # the small world's first job ends at about 180 s sim (its looping is the unit tests')
    jobs = [s["jobs"] for s in samples]
    assert jobs == sorted(jobs) and jobs[0] >= 0
    assert samples[-1]["dir_bytes"] > samples[0]["dir_bytes"] > 0
    processes = result["verdict"]["processes"]
    assert set(processes) == PROCESSES and all(p["judged"] for p in processes.values())
    assert (done.returncode == 0) == result["verdict"]["ok"]
    # one progress line per sample, the last one's too
    assert f"sim {samples[-1]['sim_s']:.0f}/90 s" in done.stderr
