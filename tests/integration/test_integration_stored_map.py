"""`fleet up --map` with a stored map of another building, end to end over real processes and
a real Zenoh router: the robots' first scans do not match the map, and the run stops naming
the map file instead of driving blind. A run that cleans on a faithful stored map is
`test_integration_moved_furniture.py` (a map of the small world as it was, with furniture
moved since), which checks the plan was made on the map."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fleet.coordinator.exploring import write_ros_map
from fleet.report.exploration import true_floor
from fleet.supervisor.fleet_processes import WRONG_MAP_EXIT
from fleet.supervisor.runner import RunningFleet
from fleet.world import load_world
from planners.grid import GridMap

pytestmark = [pytest.mark.integration, pytest.mark.timeout(300)]

WORLD = Path(__file__).resolve().parents[2] / "configs" / "worlds" / "small.yaml"


def another_building(like: GridMap) -> GridMap:
    """A map in the small world's frame, with the start poses on its floor, of another room:
    smaller (walls 0.3 m in from the world's near walls), with a pillar where the world has
    floor."""
    rows, cols = like.shape
    xy = like.cell_to_world(np.argwhere(np.ones(like.shape, bool))).reshape(rows, cols, 2)
    x, y = xy[..., 0], xy[..., 1]
    inside = (x > 0.3) & (x < 3.2) & (y > 0.3) & (y < 2.4)
    inner = (x > 0.4) & (x < 3.1) & (y > 0.4) & (y < 2.3)
    pillar = (np.abs(x - 2.6) < 0.15) & (np.abs(y - 1.0) < 0.15)
    walls = (inside & ~inner) | pillar
    return GridMap(walls, ~inside & ~walls, like.resolution, like.origin)


def test_a_stored_map_of_another_building_stops_the_run_naming_the_file(tmp_path: Path) -> None:
    world = load_world(WORLD)
    truth, _ = true_floor(world, 0.05, world.starts[0][:2])
    write_ros_map(tmp_path / "other", another_building(truth))
    map_yaml = tmp_path / "other/map.yaml"
    fleet = RunningFleet(
        tmp_path / "run", str(WORLD), 3, timeout_s=120.0, options=("--map", str(map_yaml))
    )
    report = fleet.finish(150.0)
    assert fleet.proc.returncode == WRONG_MAP_EXIT, fleet.output
    assert f"do not match the stored map {map_yaml}" in fleet.output, fleet.output
    assert report is not None and report["status"] == "wrong-map", fleet.output
    refused = fleet.events("wrong map")
    assert len(refused) == 1 and str(map_yaml.resolve()) in refused[0]["detail"], refused
    # stopped on what the robots saw at the start, long before a cleaning run would end
    assert refused[0]["sim"] < 30.0, refused
