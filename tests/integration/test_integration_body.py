"""A robot killed where its body is in the way, end to end: real processes on a real router.

On the small world with three robots at ``--speed 0``, robot-1 is SIGKILLed 5.7 s of sim time
after its first award (10.8 s into the sim on an idle machine; the clock runs while the agents
start, so the moment is counted from the job's start), beside the dock, where its body hems
robot-0 in between the dock and the wall (before the body was planned round, that run ended
"done" at 79 % after robot-0 spent half of it escaping in the pocket). Now the fleet must still
clean the floor (coverage of the floor not under the body ≥ 0.95), without contact, and say
what it could not reach: a run that finishes with floor left out ends ``incomplete``, exit
status 4, with each piece in report.json, and never ``done``.
"""

from __future__ import annotations

import signal
from pathlib import Path

import pytest
from fleet_runs import FleetRun

from fleet.bench.kill_sweep import outside_body
from fleet.cli.up import INCOMPLETE_EXIT
from fleet.params import load_fleet_config

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(400)]
KILL_AFTER_AWARD_S = 5.7


def test_a_robot_killed_in_the_way_is_planned_round_and_the_floor_still_cleaned(
    tmp_path: Path,
) -> None:
    run = FleetRun(tmp_path / "run", timeout_s=300.0)
    clock = run.clock()
    try:
        run.wait_for(lambda: run.first_award("robot-1") is not None, 120, "robot-1's award")
        at = (run.first_award("robot-1") or 0.0) + KILL_AFTER_AWARD_S
        run.wait_for(lambda: clock.t >= at, timeout=120, what=f"sim time {at:.1f} s")
        run.signal("robot-1", signal.SIGKILL)
        report = run.finish()
    finally:
        run.cleanup()
    assert run.left == [], f"processes left behind: {run.left}"
    events = run.events()
    assert any(e["kind"] == "body" and e["robot"] == "robot-1" for e in events), run.explained()
    assert any(e["kind"] == "rerouted" for e in events), run.explained()
    radius = load_fleet_config().robot.radius
    covered = outside_body(run.dir, "robot-1", radius)
    assert covered is not None and covered >= 0.95, run.explained()
    assert report["collisions"] == {"robot_wall": 0, "robot_robot": 0}, run.explained()
    assert report["overlaps"] == [], run.explained()
    left = report["left_out"]
    if left:
        assert report["status"] == "incomplete", run.explained()
        assert run.proc.returncode == INCOMPLETE_EXIT, run.explained()
        assert report["left_out_m2"] > 0 and all(p["path"] for p in left)
    else:
        assert report["status"] == "done", run.explained()
    settled = ("done", "replaced", "blocked", "unreachable")
    assert all(t["state"] in settled for t in report["tasks"]), run.explained()
