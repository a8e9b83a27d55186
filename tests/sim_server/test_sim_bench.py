"""fleet bench sim: one JSON object with the real-time factors, and errors for bad arguments."""

import json

import pytest
from typer.testing import CliRunner

from fleet.cli import app

runner = CliRunner()


def test_json_reports_rates_cpu_time_and_load() -> None:
    res = runner.invoke(
        app, ["bench", "sim", "--robots", "2", "--seconds", "3", "--world", "small", "--json"]
    )
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert out["robots"] == 2 and out["world"] == "small"
    assert out["sim_seconds"] == pytest.approx(3.0)
    assert out["scans"] == 2 * 30
    assert out["rtf_cpu"] == pytest.approx(out["sim_seconds"] / out["cpu_s"], rel=0.05)
    assert out["rtf"] > 0 and out["load_avg"] >= 0
    assert 0 < out["coverage"] < 1


def test_zero_robots_is_refused() -> None:
    res = runner.invoke(app, ["bench", "sim", "--robots", "0"])
    assert res.exit_code != 0
    assert "--robots" in res.output
