"""Batteries end to end: real processes on a real router, on the small world with two robots
whose full charge lasts 100 s of sweeping and who go to charge below 35 % (the job is about
100 s for each). Each must go to
charge once on the way, one at a time at the one dock (the other waits by it), the work each
leaves goes to the other, and the job still finishes with every robot home; `fleet dock
robot-1` sends robot-1 home early on, and it comes back to work (`--dock 1`, a dock the world
does not have, is refused first)."""

from __future__ import annotations

from pathlib import Path

import pytest
from fleet_runs import FleetRun, battery_config

from fleet.supervisor.runner import RunningFleet

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(900)]
# robot-1 is sent home this long after its first award (sim s; 15 s into an idle run's sim)
DOCK_AFTER_AWARD_S = 10.0


def test_robots_run_down_charge_and_the_job_still_finishes(tmp_path: Path) -> None:
    config = battery_config(
        tmp_path / "fleet.yaml", capacity_s=100.0, charge_rate=8.0, recharge_threshold=0.35
    )
    run = FleetRun(tmp_path / "run", robots=2, timeout_s=600.0, options=("--config", str(config)))
    clock = run.clock()
    try:
        run.wait_for(lambda: run.first_award("robot-1") is not None, 180, "robot-1's award")
        at = (run.first_award("robot-1") or 0.0) + DOCK_AFTER_AWARD_S
        run.wait_for(lambda: clock.t >= at, timeout=180, what=f"sim time {at:.1f} s")
        wrong = RunningFleet.verb(run, "dock", "robot-1", "--dock", "1")
        run.verb("dock", "robot-1")
        report = run.finish()
    finally:
        run.cleanup()
    assert run.left == [], f"processes left behind: {run.left}"
    assert wrong.returncode != 0 and "no dock 1: the world has 1 dock, from 0" in wrong.stderr, (
        wrong.stdout + wrong.stderr
    )
    events = run.events()
    homes = [(e["robot"], e["detail"]) for e in events if e["kind"] == "dock"]
    # to the dock, or to wait by it when robot-0 stands on it without work at that moment
    # (between its awards, as in one CI run): either way sent home, and charged below
    sent = {"sent home by cli: to dock 0", "sent home by cli: to wait by dock 0"}
    assert any(rid == "robot-1" and why in sent for rid, why in homes), run.explained()
    low = {rid for rid, why in homes if "below" in why}
    assert low, run.explained()  # the threshold sent a robot to charge
    charged = {e["robot"] for e in events if e["kind"] == "charged"}
    assert "robot-1" in charged, run.explained()
    reopened = [e for e in events if e["kind"] == "reopened" and "charge" in e["detail"]]
    assert reopened, run.explained()  # the work it left was sold again
    assert report["status"] == "done" and report["coverage"] >= 0.9, run.explained()
    batteries = {rid: r["battery"] for rid, r in report["robots"].items()}
    assert all(b["min_charge"] > 0 for b in batteries.values()), batteries
    assert all(b["charges"] >= 1 for b in batteries.values()), batteries
    assert sum(b["parked"] for b in batteries.values()) == 1, batteries  # one dock
    assert report["collisions"]["robot_robot"] == 0, run.explained()
