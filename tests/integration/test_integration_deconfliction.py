"""Transits planned in space and time on a running fleet: the corridor world (two rooms joined
by a corridor one robot wide) with `fleet up --deconfliction prioritized`, real processes over a
real router. The robots cross the corridor, the coordinator plans their transits together, and
the run finishes with no robot–robot contact."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from fleet.supervisor.runner import RunningFleet

pytestmark = [pytest.mark.integration, pytest.mark.timeout(400)]

WORLDS = Path(__file__).resolve().parents[2] / "configs" / "worlds"
WORLD = WORLDS / "corridor.yaml"
# the corridor runs from x = 3 to x = 5 m
LEFT_X, RIGHT_X = 3.0, 5.0


def _crossings(tracks: Path) -> int:
    """How many times a robot went from one room to the other (by its true track)."""
    side: dict[str, str] = {}
    crossed = 0
    with tracks.open() as f:
        for row in csv.DictReader(f):
            x = float(row["x"])
            now = "left" if x < LEFT_X else "right" if x > RIGHT_X else None
            if now is None:
                continue
            crossed += side.get(row["robot"], now) != now
            side[row["robot"]] = now
    return crossed


def test_the_corridor_world_is_cleaned_with_planned_transits_and_no_robot_contact(
    tmp_path: Path,
) -> None:
    fleet = RunningFleet(tmp_path, str(WORLD), 3, options=("--deconfliction", "prioritized"))
    report = fleet.finish(330.0)
    assert report is not None, fleet.output[-3000:]
    assert report["status"] == "done", fleet.output[-3000:]
    assert report["deconfliction"] == "prioritized"
    assert report["collisions"]["robot_robot"] == 0
    assert report["coverage"] >= 0.95
    rounds = [e for e in report["events"] if e["kind"] == "transits"]
    planned = [e for e in rounds if " by " in e["detail"]]
    assert planned, f"no transit round was planned: {rounds}"
    assert _crossings(tmp_path / "tracks.csv") >= 1
    assert not fleet.left, f"processes left behind: {fleet.left}"


@pytest.mark.slow
def test_a_corridor_with_a_lane_is_crossed_both_ways_with_every_round_planned(
    tmp_path: Path,
) -> None:
    """corridor_wide: a corridor 0.6 m wide that holds a lane, two robots starting in each room.
    Every round of transits is planned (the old transit graph called a lane end by a wall, and
    a goal in the corridor, unreachable: event ``unreachable``, local transits instead), and
    the floor is cleaned."""
    fleet = RunningFleet(
        tmp_path,
        str(WORLDS / "corridor_wide.yaml"),
        4,
        options=("--deconfliction", "prioritized"),
    )
    report = fleet.finish(390.0)
    assert report is not None, fleet.output[-3000:]
    assert report["status"] == "done", fleet.output[-3000:]
    assert report["deconfliction"] == "prioritized"
    unreachable = [e["detail"] for e in report["events"] if e["kind"] == "unreachable"]
    assert not unreachable, unreachable
    rounds = [e["detail"] for e in report["events"] if e["kind"] == "transits"]
    assert rounds and all(" by " in d for d in rounds), rounds
    assert report["coverage"] >= 0.95
    assert report["collisions"]["robot_robot"] == 0
    assert not fleet.left, f"processes left behind: {fleet.left}"
