"""The scale bench's measures (fleet.bench.scale) without a fleet: the CPU time of this test's
own process and of a child that burns a known amount, looks made up to give known figures,
and the coordinator's events as it writes them."""

from __future__ import annotations

import os
import subprocess
import sys
import time

from typer.testing import CliRunner

from fleet.bench.scale import Look, coordinator_times, cpu_seconds, table_lines, window_figures
from fleet.cli import app


def test_cpu_seconds_count_a_childs_busy_loop_and_not_its_sleep() -> None:
    busy = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import time\nt = time.process_time()\n"
            "while time.process_time() - t < 0.6: pass\ntime.sleep(5)",
        ]
    )
    try:
        time.sleep(2.0)  # the 0.6 s of work and then sleep
        first = cpu_seconds(busy.pid)
        time.sleep(1.0)
        second = cpu_seconds(busy.pid)
    finally:
        busy.kill()
        busy.wait()
    assert first is not None and second is not None
    assert 0.55 <= first <= 1.2  # the loop, and the interpreter's start
    assert second - first < 0.05  # asleep
    assert cpu_seconds(os.getpid()) > 0
    assert cpu_seconds(2**22 + 1) is None  # above Linux's pid_max: gone


def _look(sim: float, wall: float, cpu: dict[str, float | None]) -> Look:
    return Look(sim, wall, cpu, {n: 100 * 1024 for n in cpu})


def test_the_window_gives_the_real_time_factor_core_shares_and_cpu_per_scan() -> None:
    a = _look(10.0, 5.0, {"robot-0": 1.0, "robot-1": 2.0, "coordinator": 3.0, "sim": 0.0})
    # 40 s sim in 8 s wall: 400 scans at 10 Hz each
    b = _look(50.0, 13.0, {"robot-0": 3.0, "robot-1": 6.0, "coordinator": 3.8, "sim": 4.0})
    w = window_figures(a, b, 10.0)
    assert w["window_sim_s"] == 40.0 and w["window_wall_s"] == 8.0
    assert w["real_time_factor"] == 5.0
    assert w["processes"]["robot-0"]["cpu_ms_per_scan"] == 5.0
    assert w["processes"]["robot-1"]["cpu_ms_per_scan"] == 10.0
    assert "cpu_ms_per_scan" not in w["processes"]["coordinator"]
    assert w["processes"]["coordinator"]["core_share"] == 0.1
    assert w["agent_cpu_ms_per_scan"] == {"n": 2, "median": 7.5, "max": 10.0}
    assert w["cores_busy"] == round((2 + 4 + 0.8 + 4) / 8, 2)
    assert w["processes"]["sim"]["rss_mb"] == 100.0


def test_a_process_gone_at_either_end_has_no_share_but_the_rest_are_counted() -> None:
    a = _look(0.0, 0.0, {"robot-0": 1.0, "robot-1": None})
    b = _look(10.0, 2.0, {"robot-0": 1.5, "robot-1": 4.0})
    w = window_figures(a, b, 10.0)
    assert "core_share" not in w["processes"]["robot-1"]
    assert w["agent_cpu_ms_per_scan"] == {"n": 1, "median": 5.0, "max": 5.0}


def test_auction_time_is_per_lot_and_rounds_are_read_from_transit_events() -> None:
    events = [
        {"kind": "auction", "detail": "12 lots in 360 ms"},
        {"kind": "auction", "detail": "1 lots in 20 ms"},
        {"kind": "auction", "detail": "0 lots in 3 ms"},
        {"kind": "transits", "detail": "3 robots by prioritized in 41 ms, 0 standing"},
        {"kind": "transits", "detail": "failed: no path; local transits instead"},
        {"kind": "awarded", "detail": "lot-3: 12.0 s"},
    ]
    times = coordinator_times(events)
    assert times["auction_ms_per_lot"] == {"n": 2, "median": 25.0, "max": 30.0}
    assert times["transit_round_ms"] == {"n": 1, "median": 41.0, "max": 41.0}


def test_the_table_has_a_row_per_point_and_names_a_stopped_one() -> None:
    a = _look(0.0, 0.0, {"robot-0": 0.0, "coordinator": 0.0})
    b = _look(20.0, 4.0, {"robot-0": 1.0, "coordinator": 0.4})
    point = {"world": "small", "robots": 1} | window_figures(a, b, 10.0)
    point |= coordinator_times([{"kind": "auction", "detail": "4 lots in 100 ms"}])
    stopped = {"world": "small", "robots": 20, "stopped": "no award by 3.0 s sim"}
    lines = table_lines({"seed": 0, "window_s": 20.0, "to_end": False, "points": [point, stopped]})
    assert len(lines) == 4
    assert lines[2].split()[:4] == ["small", "1", "5.00", "5.00"]
    assert "no award" in lines[3]


def test_robot_counts_and_the_window_are_checked_before_any_run() -> None:
    runner = CliRunner()
    bad = runner.invoke(app, ["bench", "scale", "--robots", "3,zero"])
    assert bad.exit_code != 0 and "--robots" in bad.output and "zero" in bad.output
    bad = runner.invoke(app, ["bench", "scale", "--robots", "0"])
    assert bad.exit_code != 0 and "--robots" in bad.output
    bad = runner.invoke(app, ["bench", "scale", "--window", "-1"])
    assert bad.exit_code != 0 and "--window" in bad.output
