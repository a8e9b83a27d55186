"""Furniture moved since the stored map was made, end to end: the fleet cleans the small world
with a chest moved in (configs/worlds/small_moved.yaml) on a stored map of the small world as
it was, with a stool since taken away, over real processes and a real Zenoh router. The
coordinator finds the chest on the robots' maps, says where in a `map changed` event, and
re-plans the lanes that ran through it, so the job ends `done`; it finds the stool's floor
free and puts it on the map it plans on, and makes no task of its own for it. Without
the change the same run ended `incomplete` (exit 4): the lanes through the chest were tried by
every robot in vain (BENCHMARKS.md, "Stored maps: fleet up --map")."""

from __future__ import annotations

import csv
import re
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from fleet.coordinator.exploring import write_ros_map
from fleet.report.exploration import true_floor
from fleet.supervisor.runner import RunningFleet
from fleet.world import load_world
from planners.grid import GridMap

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(300)]

WORLDS = Path(__file__).resolve().parents[2] / "configs" / "worlds"
# the chest of small_moved.yaml, (xmin, ymin, xmax, ymax)
CHEST = (1.05, 2.0, 1.55, 2.4)
# a stool on the stored map that the world no longer has
STOOL = (3.0, 0.45, 3.4, 0.85)
# how far a change's cells may lie outside the furniture: a cell and a half of the robots' 5 cm maps
NEAR_M = 0.075
WHERE = re.compile(r"x (-?[\d.]+)–(-?[\d.]+), y (-?[\d.]+)–(-?[\d.]+)")


def stored_map_of_small(out: Path) -> Path:
    """The small world as it was, stored as `fleet explore` stores a map: its floor and walls
    known at 5 cm, what lies beyond them unknown, and the stool on its floor."""
    world = load_world(WORLDS / "small.yaml")
    truth, floor = true_floor(world, 0.05, world.starts[0][:2])
    walls = truth.occupied & ~floor
    rc = np.argwhere(floor)
    x, y = truth.cell_to_world(rc).T
    stool = (x > STOOL[0]) & (x < STOOL[2]) & (y > STOOL[1]) & (y < STOOL[3])
    walls[rc[stool, 0], rc[stool, 1]] = True
    write_ros_map(out, GridMap(walls, ~floor & ~walls, 0.05, truth.origin))
    return out / "map.yaml"


def _box(event: dict) -> tuple[float, float, float, float]:
    found = WHERE.search(event["detail"])
    assert found is not None, event
    x0, x1, y0, y1 = (float(v) for v in found.groups())
    return x0, y0, x1, y1


def _within(box: tuple[float, float, float, float], of: tuple[float, ...]) -> bool:
    x0, y0, x1, y1 = box
    return (
        x0 >= of[0] - NEAR_M
        and x1 <= of[2] + NEAR_M
        and y0 >= of[1] - NEAR_M
        and y1 <= of[3] + NEAR_M
    )


def test_a_chest_moved_in_is_planned_round_and_a_stool_taken_away_put_on_the_map(
    tmp_path: Path,
) -> None:
    map_yaml = stored_map_of_small(tmp_path / "map")
    fleet = RunningFleet(
        tmp_path / "run",
        str(WORLDS / "small_moved.yaml"),
        3,
        timeout_s=200.0,
        options=("--map", str(map_yaml)),
    )
    try:
        report = fleet.finish(240.0)
    finally:
        fleet.cleanup()
    assert fleet.left == [], f"processes left behind: {fleet.left}"
    assert fleet.proc.returncode == 0 and report is not None, fleet.output
    assert report["status"] == "done", fleet.output
    # planned on the stored map, not on the world file the simulator runs
    assert report["plan"]["floor"] == str(map_yaml.resolve()), report["plan"]
    assert report["floor_map"] == str(map_yaml)
    assert len(fleet.events("map checked")) == 1 and not fleet.events("wrong map"), fleet.output
    changed = fleet.events("map changed")
    added = [e for e in changed if e["detail"].startswith("an obstacle")]
    freed = [e for e in changed if e["detail"].startswith("floor where")]
    assert added and freed, fleet.output
    assert all(_within(_box(e), CHEST) for e in added), added
    assert all(_within(_box(e), STOOL) for e in freed), freed
    # no task of its own sweeps the stool's floor: the job's tasks are the tour's and their parts
    (planned,) = fleet.events("planned")
    db = sqlite3.connect(f"file:{fleet.dir / 'coordinator.sqlite'}?mode=ro", uri=True)
    try:
        kinds = db.execute("SELECT kind FROM tasks WHERE parent IS NULL").fetchall()
    finally:
        db.close()
    assert planned["detail"] == f"{len(kinds)} tasks" and set(kinds) == {("tour",)}, kinds
    # the lanes through the chest were taken back and sold again round it
    assert fleet.events("rerouted"), fleet.output
    assert report["coverage"] >= 0.9, fleet.output
    # no robot touches the chest the plan was told of (its corner once was touched, by DWA's
    # slide-out past it). Two robots meeting by the dock is a standing defect of every run on a
    # stored map (docs/notes/stored-maps.md), and a robot creeping onto the table's convex
    # corner (2.0, 1.9) after an escape one of the standing corner contacts (a run in three on
    # 7d8c9dc, docs/notes/corner-contacts.md): issue 47's, not asserted here
    with open(fleet.dir / "collisions.csv", newline="") as f:
        walls = [row for row in csv.DictReader(f) if row["kind"] == "wall"]
    at_chest = [w for w in walls if _within((float(w["x"]), float(w["y"])) * 2, CHEST)]
    assert not at_chest, (at_chest, fleet.output)
