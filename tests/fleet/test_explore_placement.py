"""A robot that started with no known pose: its map, sent in its own frame, is kept out of the
merged map and placed on it (the explorer, without a bus), and the report's placements."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fleet.config import configs_dir
from fleet.coordinator.exploring import Explorer, MapPlanner, RobotMaps, Snapshot, Survey
from fleet.coordinator.store import JobStore
from fleet.params import load_fleet_config
from fleet.protocol import MapPatches
from fleet.report.exploration import placements
from fleet.world import load_world
from planners.grid import GridMap

CFG = load_fleet_config()
RES = CFG.slam.resolution
TILE = 32
# where robot-1 stands in the home, and its heading: its own frame's origin in the fleet's
START = (3.125, 2.275, math.radians(90.0))


def _ros(grid: GridMap, known: np.ndarray) -> np.ndarray:
    """OccupancyGrid values of ``grid``: 100 occupied, 0 free, −1 where not ``known``."""
    cells = np.where(grid.occupied, 100, 0).astype(np.int8)
    cells[~known | grid.unknown] = -1
    return cells


def _home() -> GridMap:
    return load_world(configs_dir() / "worlds" / "home.yaml").grid(RES)


def _seen_from(truth: GridMap, xy: tuple[float, float], radius: float) -> np.ndarray:
    rc = np.indices(truth.shape).reshape(2, -1).T
    centres = truth.cell_to_world(rc).reshape(*truth.shape, 2)
    return np.hypot(centres[..., 0] - xy[0], centres[..., 1] - xy[1]) <= radius


def _own_frame_map(truth: GridMap, start: tuple[float, float, float], radius: float) -> GridMap:
    """What a robot standing at ``start`` maps within ``radius``, in its own frame (its origin
    at ``start``): each own-frame cell takes the true cell its centre falls on."""
    n = int(np.ceil(radius / RES)) + 2
    # own cell centres on whole cells from the origin: with START on a true cell's centre and a
    # right-angle turn, each lands on a true cell's centre (no rounding at cell borders)
    origin = (-(n + 0.5) * RES, -(n + 0.5) * RES)
    rc = np.indices((2 * n, 2 * n)).reshape(2, -1).T
    own = np.column_stack([origin[0] + (rc[:, 1] + 0.5) * RES, origin[1] + (rc[:, 0] + 0.5) * RES])
    c, s = math.cos(start[2]), math.sin(start[2])
    world = own @ np.array([[c, s], [-s, c]]) + np.array(start[:2])
    cells = truth.world_to_cell(world)
    inside = (
        (cells[:, 0] >= 0)
        & (cells[:, 0] < truth.shape[0])
        & (cells[:, 1] >= 0)
        & (cells[:, 1] < truth.shape[1])
        & (np.hypot(own[:, 0], own[:, 1]) <= radius)
    )
    occupied = np.zeros(len(rc), bool)
    free = np.zeros(len(rc), bool)
    r, k = cells[inside, 0], cells[inside, 1]
    occupied[inside] = truth.occupied[r, k]
    free[inside] = truth.free[r, k]
    shape = (2 * n, 2 * n)
    occupied, free = occupied.reshape(shape), free.reshape(shape)
    return GridMap(occupied, ~(occupied | free), RES, origin)


def _survey(seen_from: tuple[float, float], radius: float) -> Survey | None:
    """The explorer's update when robot-0 has mapped the home within ``radius`` of
    ``seen_from`` (in the fleet's frame) and robot-1, standing at START, has mapped 3 m round
    it in its own frame."""
    truth = _home()
    fleet_map = _ros(truth, _seen_from(truth, seen_from, radius))
    own = _own_frame_map(truth, START, 3.0)
    snap = Snapshot(
        {"robot-0": fleet_map, "robot-1": _ros(own, own.occupied | own.free)},
        {"robot-0": (RES, truth.origin), "robot-1": (RES, own.origin)},
        {},
        frozenset({"robot-1"}),
    )
    return Explorer(CFG, MapPlanner(CFG), None).survey(snap)


def test_a_map_in_its_own_frame_is_placed_on_the_merged_map_not_merged_into_it():
    survey = _survey((1.5, 1.5), 4.0)  # robot-0 has mapped the near end of the home
    assert survey is not None and survey.mapped == frozenset({"robot-0"})
    match = survey.placements["robot-1"]
    assert match.confident, match.reason
    t = match.transform
    assert math.hypot(t.x - START[0], t.y - START[1]) <= RES, t
    assert abs(math.degrees(t.theta - START[2])) <= 1.0, t


def test_a_map_of_a_place_the_fleet_has_not_seen_is_refused():
    survey = _survey((8.5, 5.5), 2.0)  # robot-0 knows only the far end
    assert survey is not None
    assert not survey.placements["robot-1"].confident


def _patches(cells: np.ndarray, seq: int, full: bool, own_frame: bool) -> MapPatches:
    rows, cols = cells.shape
    blocks = [
        (r, c, cells[r : r + TILE, c : c + TILE])
        for r in range(0, rows, TILE)
        for c in range(0, cols, TILE)
    ]
    return MapPatches.pack(
        float(seq), seq, full, cells.shape, RES, (0.0, 0.0), TILE, blocks, own_frame
    )


def test_patches_in_another_frame_than_the_copy_are_not_written_into_it():
    maps = RobotMaps()
    own = np.full((32, 32), -1, dtype=np.int8)
    own[10:20, 10:20] = 0
    maps.hear("robot-1", _patches(own, 1, True, own_frame=True))
    assert maps.own_frame == {"robot-1"}
    placed = np.zeros((32, 32), dtype=np.int8)
    # the whole placed map was lost: its first patches cannot be laid on the own-frame copy
    maps.hear("robot-1", _patches(placed, 3, False, own_frame=False))
    assert "robot-1" in maps.missing and np.array_equal(maps.cells["robot-1"], own)
    assert maps.own_frame == {"robot-1"}
    maps.hear("robot-1", _patches(placed, 3, True, own_frame=False))
    assert not maps.missing and not maps.own_frame
    assert np.array_equal(maps.cells["robot-1"], placed)


def test_the_report_scores_each_placement_against_the_true_start(tmp_path: Path):
    store = JobStore(tmp_path / "coordinator.sqlite")
    store.add_event(1.0, 4.7, "unplaced", "robot-2", "", "its map is not placed: overlap 0.0")
    store.add_event(2.0, 7.9, "placed", "robot-2", "", "its map matched at (3.67, 0.73, 90.0°)")
    store.close()
    out = placements(
        tmp_path / "coordinator.sqlite",
        {"robot-2": (3.64, 0.75, math.radians(91.0)), "robot-3": (1.0, 1.0, 0.0)},
    )
    assert out["robot-2"] == {
        "placed_s": 7.9,
        "error_m": pytest.approx(math.hypot(0.03, 0.02), abs=1e-3),
        "error_deg": pytest.approx(1.0, abs=0.01),
        "refused": 1,
    }
    assert out["robot-3"]["placed_s"] is None
