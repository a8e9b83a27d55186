"""`fleet explore` end to end: two robots map the small world they were never shown, over real
processes and a real Zenoh router on a free loopback port; the second is not told where it
starts, and is placed by matching its map with the first's."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fleet.floor_map import unpack_grid
from fleet.protocol import MapPatches, Request
from fleet.supervisor.runner import RunningFleet
from fleet.world import load_ros_map, load_world
from planners.grid import GridMap

pytestmark = [pytest.mark.integration, pytest.mark.timeout(300)]

WORLD = Path(__file__).resolve().parents[2] / "configs" / "worlds" / "small.yaml"


def _known_cells(fleet: RunningFleet, seen: list[int]) -> bool:
    """Ask the coordinator for the merged map (``coord/explored``, what the live view draws)
    and note how many cells it knows when that grew; whether it has grown twice."""
    bus = fleet.clock().bus
    try:
        grid = unpack_grid(bus.request(bus.keys.explored_map(), Request("test"), MapPatches, 1.0))
    except (TimeoutError, RuntimeError):
        return False
    known = int((~grid.unknown).sum())
    if not seen or known > seen[-1]:
        seen.append(known)
    return len(seen) >= 3


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> dict:
    run_dir = tmp_path_factory.mktemp("explore")
    command = ("explore", "--unknown-start", "1")
    fleet = RunningFleet(run_dir, str(WORLD), 2, timeout_s=150.0, command=command)
    served: list[int] = []
    try:
        fleet.wait(lambda: _known_cells(fleet, served), 60.0)
        fleet.finish(240.0)
    finally:
        fleet.cleanup()
    return {
        "served": served,
        "rc": fleet.proc.returncode,
        "output": fleet.output,
        "dir": run_dir,
        "left": fleet.left,
        "events": fleet.events(),
    }


def _explained(run: dict) -> str:
    warnings = [
        line
        for log in sorted(run["dir"].glob("*.log"))
        for line in log.read_text(errors="replace").splitlines()
        if " WARNING " in line or " ERROR " in line
    ]
    events = [
        f"{e['sim']:.1f} {e['kind']} {e['robot']} {e['task']} {e['detail']}" for e in run["events"]
    ]
    return "\n".join([run["output"], *events, *warnings])


def test_the_small_world_is_explored_to_the_end(run: dict) -> None:
    assert run["rc"] == 0, _explained(run)
    assert run["left"] == [], f"orphans: {run['left']}"
    report = json.loads((run["dir"] / "explore.json").read_text())
    assert report["status"] == "done", _explained(run)
    assert report["frontiers"]["assigned"] >= 1
    assert set(report["path_length_m"]) == {"robot-0", "robot-1"}
    assert any(m > 0.5 for m in report["path_length_m"].values()), report
    kinds = {e["kind"] for e in run["events"]}
    assert {"explored", "awarded", "finished"} <= kinds, kinds
    # the picture of the run: each robot's track and frontier goals, and the growth
    svg = (run["dir"] / "explore.svg").read_text()
    assert all(f'id="{i}"' in svg for i in ("track-robot-0", "track-robot-1", "growth-known"))
    assert (run["dir"] / "explore.png").stat().st_size > 0


def test_the_robot_with_an_unknown_start_is_placed_and_explores(run: dict) -> None:
    """robot-1's own frame starts where it stands: the placement the coordinator found is its
    true start pose, within two 5 cm cells and 3° (the matching itself is held to a cell and a
    degree by tests/fleet/test_explore_placement.py; a map made standing still in one spot has
    been placed 2° off on home); placed, it took frontiers and drove."""
    report = json.loads((run["dir"] / "explore.json").read_text())
    placed = report["placements"]["robot-1"]
    assert placed["placed_s"] is not None, _explained(run)
    assert placed["error_m"] <= 0.1 and placed["error_deg"] <= 3.0, placed
    owners = {e["robot"] for e in run["events"] if e["kind"] == "awarded"}
    assert "robot-1" in owners, _explained(run)
    assert report["path_length_m"]["robot-1"] > 0.3, report


def test_the_merged_map_is_served_as_it_grows(run: dict) -> None:
    # the live view's map: three answers on coord/explored, each knowing more cells
    assert len(run["served"]) >= 3, (run["served"], _explained(run))


def test_the_stored_map_loads_and_matches_the_true_floor(run: dict) -> None:
    mapped = load_ros_map(run["dir"] / "map.yaml")
    assert isinstance(mapped, GridMap) and mapped.free.any()
    report = json.loads((run["dir"] / "explore.json").read_text())
    assert report["free_iou"] >= 0.9, _explained(run)
    assert (run["dir"] / "map.png").stat().st_size > 0
    # every free cell of the stored map lies inside the room's walls
    world = load_world(WORLD)
    xmin, ymin, xmax, ymax = world.bounds
    rc = np.argwhere(mapped.free)
    xy = mapped.cell_to_world(rc)
    assert (xy[:, 0] > xmin).all() and (xy[:, 0] < xmax).all(), _explained(run)
    assert (xy[:, 1] > ymin).all() and (xy[:, 1] < ymax).all(), _explained(run)
