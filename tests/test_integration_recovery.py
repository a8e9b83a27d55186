"""The market under failure, end to end: real processes on a real router, real signals.

Each test runs the small world with three robots at ``--speed 0`` and breaks it once the first
task is done (robots are then part-way through their queues): an agent SIGKILLed and
respawned, an agent hung by SIGSTOP for 5 s with garbage on the market's keys meanwhile, the
coordinator SIGKILLed and restarted. The floor must still be cleaned, without contact, and no
task held by two robots at once.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest
from fleet_runs import FleetRun

from fleet.bus import Bus
from fleet.protocol import Award, Bid, Keys

pytestmark = [pytest.mark.integration, pytest.mark.timeout(400)]


def _check_floor(run: FleetRun, report: dict) -> None:
    assert report["status"] == "done", run.explained()
    assert report["coverage"] >= 0.95, run.explained()
    assert report["collisions"] == {"robot_wall": 0, "robot_robot": 0}, run.explained()
    assert report["overlaps"] == [], run.explained()
    assert all(t["state"] in ("done", "replaced") for t in report["tasks"]), run.explained()


def _after(events: list[dict], seq: int, kind: str, robot: str) -> list[dict]:
    return [e for e in events if e["seq"] > seq and e["kind"] == kind and e["robot"] == robot]


@pytest.fixture
def fleet(tmp_path: Path):
    run = FleetRun(tmp_path / "run")
    yield run
    run.cleanup()
    assert run.left == [], f"processes left behind: {run.left}"


def test_a_killed_agent_is_replaced_and_its_respawn_rejoins_and_sweeps(fleet: FleetRun):
    fleet.wait_for(lambda: fleet.events("done"), what="a first task done")
    fleet.verb("kill", "robot-1", "--signal", "KILL")
    fleet.wait_for(
        lambda: [e for e in fleet.events("lost") if e["robot"] == "robot-1"],
        timeout=10,
        what="robot-1 lost",
    )
    lost = next(e for e in fleet.events("lost") if e["robot"] == "robot-1")
    reopened = [e["task"] for e in fleet.events("reopened") if e["robot"] == "robot-1"]
    assert reopened, fleet.explained()
    fleet.wait_for(
        lambda: {e["task"] for e in fleet.events("reassigned")} >= set(reopened),
        timeout=10,
        what="robot-1's tasks reassigned",
    )
    fleet.verb("respawn", "robot-1")
    fleet.wait_for(
        lambda: _after(fleet.events(), lost["seq"], "rejoined", "robot-1"),
        timeout=60,
        what="robot-1 rejoined",
    )
    report = fleet.finish()
    _check_floor(fleet, report)
    events = fleet.events()
    # the respawned robot found itself in its saved map, won work and finished some of it
    assert "found itself" in (fleet.dir / "robot-1.log").read_text(), fleet.explained()
    assert _after(events, lost["seq"], "done", "robot-1"), fleet.explained()


def test_a_hung_agent_loses_its_work_and_rejoins_while_garbage_is_ignored(fleet: FleetRun):
    fleet.wait_for(lambda: fleet.events("done"), what="a first task done")
    table = json.loads((fleet.dir / "processes.json").read_text())
    keys = Keys(table["fleet"])
    with Bus("cli", "garbage", [table["endpoint"]], fleet=table["fleet"]) as bus:
        for key in (keys.bid("t00", "robot-1"), keys.award("robot-0"), keys.ack("robot-2")):
            bus.session.put(key, b"\x93not a message")
        # well-formed but out of place: a round that is not running, a robot posing as another
        bus.publish(keys.bid("t01", "robot-0"), Bid(0.0, 999, "t01", "robot-0", 1.0, 1.0, False))
        bus.publish(keys.bid("t01", "robot-2"), Bid(0.0, 1, "t01", "robot-0", 1.0, 1.0, False))
        bus.publish(
            keys.award("robot-0"),
            Award(0.0, 1, "robot-0", ["t00"], np.zeros((2, 2)), np.zeros((1, 2)), np.ones(1)),
        )
        time.sleep(0.5)
    stopped_at = time.monotonic()
    fleet.verb("kill", "robot-1", "--signal", "STOP")
    fleet.wait_for(
        lambda: [e for e in fleet.events("lost") if e["robot"] == "robot-1"],
        timeout=5,
        what="robot-1 lost while it hangs",
    )
    lost = next(e for e in fleet.events("lost") if e["robot"] == "robot-1")
    assert "heartbeat" in lost["detail"]
    time.sleep(max(0.0, 5.0 - (time.monotonic() - stopped_at)))
    fleet.verb("kill", "robot-1", "--signal", "CONT")
    fleet.wait_for(
        lambda: _after(fleet.events(), lost["seq"], "rejoined", "robot-1"),
        timeout=30,
        what="robot-1 rejoined",
    )
    report = fleet.finish()
    _check_floor(fleet, report)
    reopened = {e["task"] for e in fleet.events("reopened") if e["robot"] == "robot-1"}
    reassigned = {e["task"] for e in fleet.events("reassigned")}
    assert reopened and reopened <= reassigned, fleet.explained()
    assert report["rejected_bids"].get("late", 0) >= 1, fleet.explained()
    assert report["rejected_bids"].get("malformed", 0) >= 1, fleet.explained()
    coordinator = (fleet.dir / "coordinator.log").read_text()
    assert "dropped malformed payload" in coordinator
    assert "ignored a late bid" in coordinator
    assert "ignored a malformed bid" in coordinator
    assert "dropped malformed payload" in (fleet.dir / "robot-0.log").read_text()


def test_a_restarted_coordinator_resumes_the_job(fleet: FleetRun):
    fleet.wait_for(lambda: fleet.events("done"), what="a first task done")
    fleet.verb("kill", "coordinator", "--signal", "KILL")
    time.sleep(2.0)
    fleet.verb("respawn", "coordinator")
    fleet.wait_for(lambda: fleet.events("resumed"), timeout=60, what="the coordinator resumed")
    report = fleet.finish()
    _check_floor(fleet, report)
    planned = fleet.events("planned")
    assert len(planned) == 1, "the restarted coordinator planned the job again"
