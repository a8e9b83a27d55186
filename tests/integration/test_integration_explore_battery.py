"""`fleet up --explore` with batteries, end to end: real processes on a real router, two robots
on the small world with a second dock, each starting at 26 % of a charge that lasts 200 s of
sweeping (so each falls due within the first frontiers: `recharge_threshold` is 20 %). The
coordinator that explores sends each robot to charge when it falls due and each charges, and
the exploring ends with both home; then the fleet cleans on the map it made, charging the same
way, and finishes with no robot run out. 82-98 s of wall time on a 2-core machine, most of it
the cleaning (50-70 s: a robot waiting by a dock waits for the one on it to drive off, and
driving onto a dock takes 10-20 s of sim)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import yaml
from fleet_runs import WORLDS, FleetRun, battery_config

from fleet.supervisor.runner import read_events

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(300)]

ROBOTS = ("robot-0", "robot-1")
# a second dock, in the corner across the room from the first: the robots park at the end of
# each stage at once (robots due pick the near dock and wait by it: its charge is quick)
SECOND_DOCK = [3.4, 2.55, -math.pi / 2]


def _world(path: Path) -> Path:
    data = yaml.safe_load((WORLDS / "small.yaml").read_text())
    data["docks"] = [SECOND_DOCK]
    path.write_text(yaml.safe_dump(data))
    return path


def _due(event: dict) -> bool:
    """Whether ``event`` sends a robot to charge on its charge: below its go-home point, early
    to stagger the charges, or idle below full when an auction sold it none of the open work
    (``fleet.coordinator.charging``; in a CI run robot-1's first frontier was unreachable from
    the dock at 4.8 s, and it went to charge so at 0.26 before it fell due)."""
    detail = event["detail"]
    return event["kind"] == "dock" and (
        "below" in detail
        or "charging early" in detail
        or detail.startswith("can do none of the open work on")
    )


def _due_and_charged(events: list[dict], stage: str) -> list[str]:
    """What went wrong with the charges of one stage's events: a robot that ran out, or one
    sent to charge on falling due (below its go-home point, or early) that did not charge
    after."""
    wrong = [
        f"{stage}: {e['robot']} ran out at {e['sim']:.1f} s" for e in events if e["kind"] == "empty"
    ]
    for e in events:
        due = _due(e)
        charged = [
            c
            for c in events
            if c["kind"] == "charging" and c["robot"] == e["robot"] and c["sim"] > e["sim"]
        ]
        if due and not charged:
            wrong.append(f"{stage}: {e['robot']} sent at {e['sim']:.1f} s did not charge")
    return wrong


def test_exploring_with_batteries_charges_each_robot_when_due_and_the_fleet_cleans_after(
    tmp_path: Path,
) -> None:
    config = battery_config(
        tmp_path / "fleet.yaml", capacity_s=200.0, charge_rate=10.0, start_charge=0.26
    )
    options = ("--config", str(config), "--explore")
    world = str(_world(tmp_path / "small.yaml"))
    run = FleetRun(tmp_path / "run", robots=2, world=world, timeout_s=240.0, options=options)
    try:
        report = run.finish()
    finally:
        run.cleanup()
    explored = read_events(run.dir / "explore" / "coordinator.sqlite")
    told = "\n".join(
        f"explore {e['sim']:.1f} {e['kind']} {e['robot']} {e['task']} {e['detail']}"
        for e in explored
        if e["kind"] != "explored"
    )
    assert run.left == [], f"processes left behind: {run.left}"
    assert run.proc.returncode == 0, f"{told}\n{run.explained()}"
    assert report["status"] == "done" and report["explored"]["status"] == "done", told
    # while exploring, each robot fell due and was sent to charge on its charge, and charged
    # on a dock before the exploring ended (whether it went back to work after depends on the
    # frontiers left then: its trip to the dock may have shown the last of them)
    finished = min(e["sim"] for e in explored if e["kind"] == "finished")
    for rid in ROBOTS:
        due = [e["sim"] for e in explored if e["robot"] == rid and _due(e)]
        charging = [e["sim"] for e in explored if e["kind"] == "charging" and e["robot"] == rid]
        # (charging may come on the very step the exploring finishes: the log has it first)
        assert due and charging and due[0] < charging[0] <= finished, f"{rid}\n{told}"
    wrong = _due_and_charged(explored, "exploring") + _due_and_charged(run.events(), "cleaning")
    assert not wrong, f"{wrong}\n{told}\n{run.explained()}"
    batteries = {rid: r["battery"] for rid, r in report["robots"].items()}
    assert all(b["min_charge"] > 0 for b in batteries.values()), batteries
    assert json.loads((run.dir / "explore" / "explore.json").read_text())["status"] == "done"
