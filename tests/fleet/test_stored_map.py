"""Planning the cleaning on a stored ROS map (`fleet up --map`): the coordinator's tasks come
from the map, the dock and starts from the world, and a map not in the world's frame is
refused naming the file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fleet.config import ConfigError
from fleet.coordinator.exploring import write_ros_map
from fleet.coordinator.planning import TaskPlanner
from fleet.params import load_fleet_config
from fleet.world import load_world, on_stored_map
from planners.grid import GridMap
from planners.polyline import densify

WORLDS = Path(__file__).resolve().parents[2] / "configs" / "worlds"
# home's wall between the bedroom and the bathroom: x = 4.0, y 3.5 to 6.5
WALL_X, WALL_Y = 4.0, (3.5, 6.5)


def _near_the_wall(planner: TaskPlanner) -> int:
    """Tour points within 10 cm of the bedroom | bathroom wall's line, away from its ends."""
    pts = np.vstack([densify(np.asarray(t.path, dtype=float), 0.025) for t in planner.tasks()])
    return int(
        (
            (np.abs(pts[:, 0] - WALL_X) < 0.1)
            & (pts[:, 1] > WALL_Y[0] + 0.3)
            & (pts[:, 1] < WALL_Y[1] - 0.3)
        ).sum()
    )


def test_a_map_without_a_wall_plans_lanes_where_the_wall_stood(tmp_path: Path):
    cfg = load_fleet_config(None)
    world = load_world(WORLDS / "home.yaml", cfg.robot.radius)
    truth = world.grid(0.05)
    occupied = truth.occupied.copy()
    xy = truth.cell_to_world(np.argwhere(occupied))
    gone = (np.abs(xy[:, 0] - WALL_X) < 0.1) & (xy[:, 1] > WALL_Y[0] + 0.1)
    gone &= xy[:, 1] < WALL_Y[1] - 0.1
    rows, cols = np.argwhere(occupied)[gone].T
    occupied[rows, cols] = False
    write_ros_map(tmp_path, GridMap(occupied, truth.unknown, 0.05, truth.origin))

    on_map = TaskPlanner(on_stored_map(world, tmp_path / "map.yaml"), cfg)
    assert _near_the_wall(on_map) > 0
    assert on_map.meta["tour"]["floor"] == str(tmp_path / "map.yaml")
    # the dock is the world's
    assert on_map.dock == tuple(world.starts[0][:2])
    # on the world file no robot centre comes that close to the wall
    assert _near_the_wall(TaskPlanner(world, cfg)) == 0


@pytest.mark.parametrize("shift", [(3.0, 2.0), (0.0, -1.0), (-20.0, 0.0)])
def test_a_map_with_an_origin_off_the_worlds_frame_is_refused_naming_it(
    tmp_path: Path, shift: tuple[float, float]
):
    world = load_world(WORLDS / "small.yaml")
    truth = world.grid(0.05)
    origin = (truth.origin[0] + shift[0], truth.origin[1] + shift[1])
    write_ros_map(tmp_path, GridMap(truth.occupied, truth.unknown, 0.05, origin))
    with pytest.raises(ConfigError) as e:
        on_stored_map(world, tmp_path / "map.yaml")
    assert str(tmp_path / "map.yaml") in str(e.value) and "origin" in str(e.value)
    # the same map in the world's frame is taken
    write_ros_map(tmp_path, truth)
    stored = on_stored_map(world, tmp_path / "map.yaml")
    assert stored.map_grid is not None
    # the world's docks and starts stay the world's
    assert stored.docks == world.docks and stored.starts == world.starts


def test_a_missing_or_broken_map_is_refused_naming_the_file_and_the_field(tmp_path: Path):
    world = load_world(WORLDS / "small.yaml")
    with pytest.raises(ConfigError, match=str(tmp_path / "none.yaml")):
        on_stored_map(world, tmp_path / "none.yaml")
    write_ros_map(tmp_path, world.grid(0.05))
    text = (tmp_path / "map.yaml").read_text()
    (tmp_path / "map.yaml").write_text(text.replace("resolution: 0.05", "resolution: -1"))
    with pytest.raises(ConfigError, match=rf"{tmp_path / 'map.yaml'}: resolution"):
        on_stored_map(world, tmp_path / "map.yaml")
