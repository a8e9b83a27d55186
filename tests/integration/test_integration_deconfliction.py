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

WORLD = Path(__file__).resolve().parents[2] / "configs" / "worlds" / "corridor.yaml"
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
    fleet = RunningFleet(
        tmp_path, str(WORLD), 3, timeout_s=240.0, options=("--deconfliction", "prioritized")
    )
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
