"""World loading: the built-in worlds, a real ROS map, and errors that name file and field."""

from __future__ import annotations

import math
from itertools import combinations
from pathlib import Path

import numpy as np
import pytest
import yaml
from PIL import Image

from fleet.config import ConfigError, configs_dir
from fleet.params import default_config_path, load_fleet_config
from fleet.world import load_ros_map, load_world, turned_world
from planners.grid import clearance, reachable

RADIUS = 0.17
# a fleet.yaml must describe the robot; the tests of other sections take the built-in one
ROBOT_SECTION = yaml.safe_dump(
    {"robot": yaml.safe_load(default_config_path().read_text())["robot"]}
)
WORLDS = configs_dir() / "worlds"
SHARED = Path(__file__).resolve().parents[3] / "shared"
APARTMENT = SHARED / "data" / "maps" / "cob_ipa_apartment.yaml"


def _free_area(world, resolution: float = 0.05) -> float:
    return float(world.grid(resolution).free.sum()) * resolution**2


def _assert_spread(world, poses: list[tuple[float, float, float]], radius: float) -> None:
    xy = np.array([p[:2] for p in poses])
    assert np.all(world.clearance(xy) >= radius), world.clearance(xy)
    for a, b in combinations(xy, 2):
        assert math.dist(a, b) >= 2 * radius


# ---------------------------------------------------------------------------------------------
# Built-in worlds and a real ROS map


def test_home_world_loads() -> None:
    world = load_world(WORLDS / "home.yaml")
    assert world.name == "home"
    assert 45.0 <= _free_area(world) <= 70.0
    names = [f.name for f in world.furniture]
    assert "dock" in names
    assert len(names) - 1 >= 6
    assert len(world.starts) == 3
    assert world.dock is not None


def test_home_start_poses_extend_the_listed_starts() -> None:
    world = load_world(WORLDS / "home.yaml")
    poses = world.start_poses(6, RADIUS)
    assert len(poses) == 6
    assert poses[:3] == list(world.starts)
    _assert_spread(world, poses, RADIUS)


def test_small_world_loads() -> None:
    world = load_world(WORLDS / "small.yaml")
    assert world.name == "small"
    # 4 m × 3 m inside the wall centre lines, minus half walls and the 0.8 × 0.6 m table.
    assert 10.0 <= _free_area(world) <= 12.0
    assert [f.name for f in world.furniture] == ["table", "dock"]
    assert len(world.starts) == 3
    xmin, ymin, xmax, ymax = world.bounds
    assert xmin == pytest.approx(-0.05) and xmax == pytest.approx(4.05)
    assert ymin == pytest.approx(-0.05) and ymax == pytest.approx(3.05)
    _assert_spread(world, world.start_poses(3, RADIUS), RADIUS)


def test_corridor_world_joins_two_rooms_by_a_passage_one_robot_wide() -> None:
    world = load_world(WORLDS / "corridor.yaml")
    assert world.name == "corridor"
    g = world.grid(0.025)
    clear = clearance(g)
    # the corridor's middle: room for one robot centre line, not for two robots side by side
    row, col = g.world_to_cell(np.array([[4.0, 1.45]]))[0]
    assert RADIUS < clear[row, col] < 2 * RADIUS
    left, right = g.world_to_cell(np.array([[1.5, 1.5], [6.5, 1.0]]))
    reach = reachable(clear >= RADIUS, left[None, :])
    assert reach[right[0], right[1]]  # a robot gets from one room to the other
    _assert_spread(world, world.start_poses(3, RADIUS), RADIUS)


def test_grid_marks_furniture_occupied_and_room_free() -> None:
    world = load_world(WORLDS / "small.yaml")
    g = world.grid(0.05)
    table, middle_of_floor, wall = (2.4, 1.6), (1.0, 2.0), (4.0, 1.5)
    cells = g.world_to_cell(np.array([table, middle_of_floor, wall]))
    assert g.occupied[cells[0, 0], cells[0, 1]]
    assert not g.occupied[cells[1, 0], cells[1, 1]]
    assert g.occupied[cells[2, 0], cells[2, 1]]


@pytest.fixture(scope="module")
def apartment():
    if not APARTMENT.exists():
        pytest.skip(f"{APARTMENT} is absent (the shared data set is not installed)")
    return load_world(APARTMENT)


def test_ros_map_loads_with_its_free_area(apartment) -> None:
    assert apartment.map_grid is not None
    assert _free_area(apartment) == pytest.approx(310.0, rel=0.10)
    grid = load_ros_map(APARTMENT)
    assert grid.resolution == pytest.approx(0.05)
    assert grid.origin == pytest.approx((-19.2, -19.2))
    assert float(grid.free.sum()) * 0.05**2 == pytest.approx(310.0, rel=0.10)
    assert grid.unknown.any() and grid.occupied.any()


def test_ros_map_start_poses_are_free(apartment) -> None:
    poses = apartment.start_poses(4, RADIUS)
    assert len(poses) == 4
    _assert_spread(apartment, poses, RADIUS)
    g = apartment.grid(0.05)
    cells = g.world_to_cell(np.array([p[:2] for p in poses]))
    assert g.free[cells[:, 0], cells[:, 1]].all()


# ---------------------------------------------------------------------------------------------
# Errors


SMALL_ROOM = """\
name: room
walls:
  - [0.0, 0.0, 3.0, 0.0]
  - [3.0, 0.0, 3.0, 2.0]
  - [3.0, 2.0, 0.0, 2.0]
  - [0.0, 2.0, 0.0, 0.0]
"""


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _error(path: Path) -> str:
    with pytest.raises(ConfigError) as info:
        load_world(path, RADIUS)
    return str(info.value)


def _pgm(path: Path, pixels: np.ndarray) -> None:
    Image.fromarray(pixels.astype(np.uint8), mode="L").save(path)


def _ros_yaml(path: Path, image: str = "map.pgm", **extra: object) -> Path:
    fields = {
        "image": image,
        "resolution": 0.05,
        "origin": "[0.0, 0.0, 0.0]",
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
        **extra,
    }
    return _write(path, "".join(f"{k}: {v}\n" for k, v in fields.items()))


def _room_pixels() -> np.ndarray:
    """A 40 × 60 cell room: black border, white floor."""
    px = np.full((40, 60), 254)
    px[:2, :] = px[-2:, :] = px[:, :2] = px[:, -2:] = 0
    return px


def test_valid_temp_world_loads(tmp_path: Path) -> None:
    """The base of the error cases below is itself valid."""
    world = load_world(
        _write(tmp_path / "room.yaml", SMALL_ROOM + "starts:\n  - [1.0, 1.0, 0.0]\n")
    )
    assert world.starts == ((1.0, 1.0, 0.0),)
    _pgm(tmp_path / "map.pgm", _room_pixels())
    assert load_world(_ros_yaml(tmp_path / "map.yaml")).map_grid.free.any()


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "nowhere.yaml"
    msg = _error(path)
    assert str(path) in msg and "not found" in msg


def test_bad_yaml_names_the_line(tmp_path: Path) -> None:
    path = _write(tmp_path / "bad.yaml", "name: x\nwalls:\n  - [0, 0, 1, 0\nstarts: []\n")
    msg = _error(path)
    assert str(path) in msg
    assert "line 4" in msg or "line 3" in msg, msg


def test_unknown_top_level_field(tmp_path: Path) -> None:
    path = _write(tmp_path / "w.yaml", SMALL_ROOM + "colour: blue\n")
    msg = _error(path)
    assert str(path) in msg and "colour" in msg


def test_unknown_furniture_field(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "w.yaml",
        SMALL_ROOM + "furniture:\n  - {name: t, center: [1, 1], size: [0.5, 0.5], height: 1}\n",
    )
    msg = _error(path)
    assert str(path) in msg and "furniture[0]" in msg and "height" in msg


def test_start_inside_a_wall(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "w.yaml", SMALL_ROOM + "starts:\n  - [1.0, 1.0, 0]\n  - [3.0, 1.0, 0]\n"
    )
    msg = _error(path)
    assert str(path) in msg and "starts[1]" in msg


def test_a_world_loaded_without_a_robot_checks_only_that_its_starts_are_free(
    tmp_path: Path,
) -> None:
    near_wall = _write(tmp_path / "near.yaml", SMALL_ROOM + "starts:\n  - [0.15, 1.0, 0]\n")
    assert load_world(near_wall).starts == ((0.15, 1.0, 0.0),)
    with pytest.raises(ConfigError, match="closer than the robot radius"):
        load_world(near_wall, RADIUS)
    in_wall = _write(tmp_path / "in.yaml", SMALL_ROOM + "starts:\n  - [3.0, 1.0, 0]\n")
    with pytest.raises(ConfigError, match=r"starts\[0\].* is inside an obstacle \("):
        load_world(in_wall)


def test_a_world_names_several_docks_and_keeps_dock(tmp_path: Path) -> None:
    """``dock:`` is the first dock, ``docks:`` adds more; each gets a body behind its pose."""
    text = SMALL_ROOM + "dock: [0.5, 1.0, 0.0]\ndocks:\n  - [1.5, 0.4, 1.5707963267948966]\n"
    world = load_world(_write(tmp_path / "w.yaml", text), RADIUS)
    assert world.docks == ((0.5, 1.0, 0.0), (1.5, 0.4, math.pi / 2))
    assert world.dock == (0.5, 1.0, 0.0)
    assert [f.name for f in world.furniture] == ["dock", "dock 1"]
    assert load_world(WORLDS / "home.yaml").docks == ((3.2, 0.55, math.pi / 2),)


def test_a_dock_inside_a_wall_is_refused_naming_it(tmp_path: Path) -> None:
    """Named by the file's own field: beside ``dock:``, the list's first entry is docks[0]."""
    text = SMALL_ROOM + "dock: [0.5, 1.0, 0.0]\ndocks:\n  - [3.0, 1.0, 0.0]\n"
    msg = _error(_write(tmp_path / "w.yaml", text))
    assert str(tmp_path / "w.yaml") in msg and "docks[0]" in msg and "inside an obstacle" in msg
    listed = SMALL_ROOM + "docks:\n  - [0.5, 1.0, 0.0]\n  - [1.5, 0.4, 1.57]\n  - [3.0, 1.0, 0]\n"
    msg = _error(_write(tmp_path / "l.yaml", listed))
    assert str(tmp_path / "l.yaml") in msg and "docks[2]" in msg and "inside an obstacle" in msg


def test_a_dock_out_of_reach_is_refused_naming_it(tmp_path: Path) -> None:
    """A dock on free floor the robots cannot get to (a closed box in the room) is refused
    when the world is loaded for a robot; loaded for its floor plan alone it is not checked."""
    box = "  - [2.0, 0.3, 3.0, 0.3]\n  - [3.0, 0.3, 3.0, 1.3]\n  - [3.0, 1.3, 2.0, 1.3]\n"
    box += "  - [2.0, 1.3, 2.0, 0.3]\n"
    text = SMALL_ROOM + box + "docks:\n  - [0.5, 1.0, 0.0]\n  - [2.5, 0.8, 0.0]\n"
    path = _write(tmp_path / "w.yaml", text)
    msg = _error(path)
    assert str(path) in msg and "docks[1]" in msg and "out of reach" in msg
    assert load_world(path).docks[1] == (2.5, 0.8, 0.0)


def test_start_inside_furniture(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "w.yaml",
        SMALL_ROOM
        + "furniture:\n  - {center: [1.5, 1.0], size: [0.6, 0.6]}\nstarts:\n  - [1.6, 1.1, 0]\n",
    )
    msg = _error(path)
    assert str(path) in msg and "starts[0]" in msg


def test_start_out_of_bounds(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "w.yaml", SMALL_ROOM + "starts:\n  - [1.0, 1.0, 0]\n  - [7.0, 1.0, 0]\n"
    )
    msg = _error(path)
    assert str(path) in msg and "starts[1]" in msg and "outside" in msg


def test_overlapping_starts(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "w.yaml", SMALL_ROOM + "starts:\n  - [1.0, 1.0, 0]\n  - [1.2, 1.0, 0]\n"
    )
    msg = _error(path)
    assert str(path) in msg and "starts[1]" in msg and "starts[0]" in msg


def test_start_with_two_numbers(tmp_path: Path) -> None:
    path = _write(tmp_path / "w.yaml", SMALL_ROOM + "starts:\n  - [1.0, 1.0]\n")
    msg = _error(path)
    assert str(path) in msg and "starts[0]" in msg


def test_ros_map_image_missing(tmp_path: Path) -> None:
    path = _ros_yaml(tmp_path / "map.yaml", image="gone.pgm")
    msg = _error(path)
    assert str(path) in msg and "image" in msg and "gone.pgm" in msg


def test_ros_map_thresholds_in_wrong_order(tmp_path: Path) -> None:
    _pgm(tmp_path / "map.pgm", _room_pixels())
    path = _ros_yaml(tmp_path / "map.yaml", occupied_thresh=0.3, free_thresh=0.3)
    msg = _error(path)
    assert str(path) in msg and "free_thresh" in msg and "occupied_thresh" in msg


def test_ros_map_without_free_cell(tmp_path: Path) -> None:
    _pgm(tmp_path / "map.pgm", np.zeros((20, 20)))
    path = _ros_yaml(tmp_path / "map.yaml")
    msg = _error(path)
    assert str(path) in msg and "image" in msg and "free" in msg
    with pytest.raises(ConfigError, match="free"):
        load_ros_map(path)


def test_ros_map_unknown_field(tmp_path: Path) -> None:
    _pgm(tmp_path / "map.pgm", _room_pixels())
    msg = _error(_ros_yaml(tmp_path / "map.yaml", rotation=0))
    assert "map.yaml" in msg and "rotation" in msg


def test_world_pointing_at_missing_ros_map(tmp_path: Path) -> None:
    path = _write(tmp_path / "w.yaml", "name: w\nmap: maps/absent.yaml\n")
    msg = _error(path)
    assert str(path) in msg, msg
    assert "map" in msg and "absent.yaml" in msg


def test_world_on_a_ros_map_checks_its_starts(tmp_path: Path) -> None:
    _pgm(tmp_path / "map.pgm", _room_pixels())
    _ros_yaml(tmp_path / "map.yaml")
    good = load_world(_write(tmp_path / "ok.yaml", "map: map.yaml\nstarts:\n  - [1.5, 1.0, 0]\n"))
    assert good.map_grid is not None and good.starts == ((1.5, 1.0, 0.0),)
    path = _write(tmp_path / "w.yaml", "map: map.yaml\nstarts:\n  - [0.02, 1.0, 0]\n")
    msg = _error(path)
    assert str(path) in msg and "starts[0]" in msg


# ---------------------------------------------------------------------------------------------
# fleet.yaml


def test_fleet_config_loads_default() -> None:
    cfg = load_fleet_config()
    assert cfg.robot.radius > 0 and cfg.lidar.rate_hz == pytest.approx(10.0)


def test_fleet_config_unknown_field(tmp_path: Path) -> None:
    path = _write(tmp_path / "fleet.yaml", ROBOT_SECTION + "lidar:\n  beamz: 10\n")
    with pytest.raises(ConfigError) as info:
        load_fleet_config(path)
    msg = str(info.value)
    assert str(path) in msg and "lidar" in msg and "beamz" in msg


def test_fleet_config_unknown_section(tmp_path: Path) -> None:
    path = _write(tmp_path / "fleet.yaml", "robots:\n  radius: 0.2\n")
    with pytest.raises(ConfigError) as info:
        load_fleet_config(path)
    assert str(path) in str(info.value) and "robots" in str(info.value)


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ("sim:\n  physics_hz: fast\n", "sim.physics_hz"),
        ("lidar:\n  beams: 36.5\n", "lidar.beams"),
        ("robot:\n  radius: true\n", "robot.radius"),
        ("odometry:\n  rate_hz: [50]\n", "odometry.rate_hz"),
    ],
)
def test_fleet_config_wrong_type_names_dotted_field(tmp_path: Path, text: str, field: str) -> None:
    robot = "" if text.startswith("robot:") else ROBOT_SECTION
    path = _write(tmp_path / "fleet.yaml", robot + text)
    with pytest.raises(ConfigError) as info:
        load_fleet_config(path)
    msg = str(info.value)
    assert str(path) in msg and field in msg, msg


def test_fleet_config_validate_names_the_section(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "fleet.yaml", ROBOT_SECTION + "lidar:\n  range_min: 5.0\n  range_max: 1.0\n"
    )
    with pytest.raises(ConfigError) as info:
        load_fleet_config(path)
    assert str(path) in str(info.value) and "lidar" in str(info.value)


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ("wall_follow:\n  distance: 0.15\n", "wall_follow.distance"),  # inside the robot
        ("wall_follow:\n  reach: 0.1\n", "reach"),
        ("agent:\n  edge_cover: 1.5\n", "edge_cover"),
    ],
)
def test_fleet_config_edge_pass_fields_are_checked(tmp_path: Path, text: str, field: str) -> None:
    path = _write(tmp_path / "fleet.yaml", ROBOT_SECTION + text)
    with pytest.raises(ConfigError) as info:
        load_fleet_config(path)
    assert str(path) in str(info.value) and field in str(info.value), str(info.value)


def test_a_turned_world_keeps_its_floor_and_turns_its_walls_poses_and_bounds() -> None:
    home = load_world(WORLDS / "home.yaml", RADIUS)
    turned = turned_world(home, 20.0)
    assert turned.name == "home-turned20"
    x0, y0, x1, y1 = home.bounds
    centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    a = math.radians(20.0)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    # the sofa's corners and the first start pose, turned about the centre of the bounds
    sofa = turned.furniture[0].polygon
    assert np.allclose(sofa, (home.furniture[0].polygon - centre) @ rot.T + centre)
    (sx, sy, st), (tx, ty, tt) = home.starts[0], turned.starts[0]
    assert np.allclose([tx, ty], rot @ (np.array([sx, sy]) - centre) + centre)
    assert math.isclose(math.remainder(tt - st - a, 2 * math.pi), 0.0, abs_tol=1e-12)
    # every wall lies within the new bounds, and the floor is as large (within the raster)
    bx0, by0, bx1, by1 = turned.bounds
    corners = np.vstack(turned.walls)
    assert corners[:, 0].min() >= bx0 - 1e-9 and corners[:, 0].max() <= bx1 + 1e-9
    assert corners[:, 1].min() >= by0 - 1e-9 and corners[:, 1].max() <= by1 + 1e-9

    def floor(world) -> float:
        grid = world.grid(0.025)
        start = grid.world_to_cell(np.array(world.starts[0][:2]))
        return float(reachable(grid.free, start[None, :]).sum()) * 0.025**2

    assert floor(turned) == pytest.approx(floor(home), rel=0.02)
    # no wall runs along an axis any more
    edges = np.diff(np.vstack([home.walls[0], home.walls[0][:1]]), axis=0)
    turned_edges = np.diff(np.vstack([turned.walls[0], turned.walls[0][:1]]), axis=0)
    assert np.any(np.abs(edges).min(axis=1) < 1e-9)
    assert np.all(np.abs(turned_edges).min(axis=1) > 0.01 * np.hypot(*turned_edges.T))


def test_a_map_world_is_not_turned_and_the_error_names_its_file() -> None:
    if not APARTMENT.exists():
        pytest.skip(f"{APARTMENT} is absent (../shared holds the recorded apartment)")
    world = load_world(APARTMENT, RADIUS)
    with pytest.raises(ConfigError, match="cob_ipa_apartment"):
        turned_world(world, 20.0)
