"""Transits planned in space and time on a running fleet: `fleet up --deconfliction
prioritized` on corridor_wide (two rooms joined by a corridor 3 m long and 0.6 m between the
walls' faces, one robot wide with room for a lane inside it; two robots start in each room),
real processes over a real router. The robots cross the corridor, the coordinator plans their
transits together, every goal in the corridor is reached, and the floor is cleaned with no
robot–robot contact. The corridor world (0.5 m, no lane inside) is run by `fleet bench
deconfliction --fleet-seeds`, and corridors of every width by its `--family`: one fleet on a
corridor world is what the suite's time allows, and this one holds every check the corridor
world's test had."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from fleet.supervisor.runner import RunningFleet

pytestmark = [
    pytest.mark.integration,
    pytest.mark.slow,
    pytest.mark.long,
    pytest.mark.timeout(400),
]

WORLD = Path(__file__).resolve().parents[2] / "configs" / "worlds" / "corridor_wide.yaml"
# the corridor runs from x = 6 to x = 9 m
LEFT_X, RIGHT_X = 6.0, 9.0


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


def test_a_corridor_with_a_lane_is_crossed_with_every_round_planned(tmp_path: Path) -> None:
    """Every round of transits is planned (the old transit graph called a lane end by a wall,
    and a goal in the corridor, unreachable: event ``unreachable``, local transits instead),
    and the floor is cleaned."""
    fleet = RunningFleet(tmp_path, str(WORLD), 4, options=("--deconfliction", "prioritized"))
    report = fleet.finish(390.0)
    assert report is not None, fleet.output[-3000:]
    assert report["status"] == "done", fleet.output[-3000:]
    assert report["deconfliction"] == "prioritized"
    unreachable = [e["detail"] for e in report["events"] if e["kind"] == "unreachable"]
    assert not unreachable, unreachable
    rounds = [e["detail"] for e in report["events"] if e["kind"] == "transits"]
    assert rounds and all(" by " in d for d in rounds), rounds
    assert _crossings(tmp_path / "tracks.csv") >= 1
    assert report["coverage"] >= 0.95
    assert report["collisions"]["robot_robot"] == 0
    assert not fleet.left, f"processes left behind: {fleet.left}"
