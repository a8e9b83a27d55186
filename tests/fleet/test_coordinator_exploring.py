"""The exploring coordinator's parts without a bus: copies of the robots' maps from their
patches, the merged map's frontiers as tasks, the map written for map_server, and the market
that calls only robots without work."""

from __future__ import annotations

import threading
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from fleet.coordinator.explore_part import ExplorePart
from fleet.coordinator.exploring import Explorer, MapPlanner, RobotMaps, write_ros_map
from fleet.coordinator.job import ASSIGNED, GONE, OPEN, UNREACHABLE, Job
from fleet.coordinator.journal import Journal
from fleet.coordinator.market import Market
from fleet.coordinator.parts import Parts
from fleet.floor_map import apply_patches
from fleet.params import load_fleet_config
from fleet.protocol import Keys, MapPatches
from fleet.world import load_ros_map
from planners.grid import GridMap

CFG = load_fleet_config()
RES = CFG.slam.resolution
TILE = 32


def patches(cells: np.ndarray, seq: int, full: bool = True) -> MapPatches:
    """Every tile of ``cells`` (OccupancyGrid values, a whole number of tiles)."""
    rows, cols = cells.shape
    blocks = [
        (r, c, cells[r : r + TILE, c : c + TILE])
        for r in range(0, rows, TILE)
        for c in range(0, cols, TILE)
    ]
    return MapPatches.pack(float(seq), seq, full, cells.shape, RES, (0.0, 0.0), TILE, blocks)


def room(door: bool) -> np.ndarray:
    """A 2.4 m square room (cells 8..55) seen whole in a 64 × 96 map, unknown around it, with
    (``door``) a 1 m opening in its east wall, seen free."""
    cells = np.full((64, 96), -1, dtype=np.int8)
    cells[8:56, 8:56] = 0
    cells[8, 8:56] = cells[55, 8:56] = 100
    cells[8:56, 8] = cells[8:56, 55] = 100
    if door:
        cells[22:42, 55] = 0
    return cells


def test_a_robots_map_copy_takes_a_whole_map_then_its_changed_tiles():
    first = room(door=False)
    copy = apply_patches(None, patches(first, 1))
    assert np.array_equal(copy, first)
    opened = room(door=True)
    tile = MapPatches.pack(
        2.0, 2, False, first.shape, RES, (0, 0), TILE, [(0, 32, opened[:32, 32:64])]
    )
    updated = apply_patches(copy, tile)
    assert np.array_equal(updated[:32], opened[:32]) and np.array_equal(updated[32:], first[32:])
    assert np.array_equal(copy, first)  # the old copy is left as it was
    with pytest.raises(ValueError, match="never received"):
        apply_patches(None, tile)


def test_a_gap_in_the_patches_asks_for_the_whole_map_until_it_comes():
    maps = RobotMaps()
    maps.hear("robot-0", patches(room(False), 1))
    assert not maps.missing
    maps.hear("robot-0", patches(room(False), 3, full=False))  # 2 was lost
    assert maps.missing == {"robot-0"}
    maps.hear("robot-0", patches(room(True), 3))  # the whole map, by query
    assert not maps.missing and np.array_equal(maps.cells["robot-0"], room(True))
    maps.hear("robot-1", patches(room(True), 5, full=False))  # a tile before any whole map
    assert "robot-1" in maps.missing and "robot-1" not in maps.cells


def test_the_merged_map_is_written_as_a_map_server_pair_that_loads(tmp_path: Path):
    occupied = np.zeros((20, 30), dtype=bool)
    unknown = np.zeros((20, 30), dtype=bool)
    occupied[0, :] = True
    unknown[1:, 25:] = True
    grid = GridMap(occupied, unknown, 0.05, (-1.25, 2.5))
    write_ros_map(tmp_path, grid)
    back = load_ros_map(tmp_path / "map.yaml")
    assert back.resolution == 0.05 and back.origin == pytest.approx((-1.25, 2.5))
    assert np.array_equal(back.occupied, occupied) and np.array_equal(back.unknown, unknown)


def _job(*robots: str) -> Job:
    job = Job(CFG.coverage, CFG.robot, CFG.coordinator.wall_clearance)
    for rid in robots:
        r = job.robot(rid)
        r.ready, r.xy = True, (1.6, 1.6)  # the room's middle
    return job


def test_frontiers_become_tasks_vanish_with_their_frontier_and_the_end_follows(tmp_path: Path):
    explorer = Explorer(CFG, MapPlanner(CFG), tmp_path)
    job = _job("robot-0")
    assert explorer.update(job) is None  # no map yet
    explorer.maps.hear("robot-0", patches(room(door=True), 1))
    change = explorer.update(job)
    assert change is not None and change.frontiers == 1 and len(change.added) == 1
    task = change.added[0]
    assert job.tasks[task.id].state == OPEN
    # the goal is at the doorway, on the known side
    assert task.entry[0] == pytest.approx(2.775, abs=0.1) and 1.1 < task.entry[1] < 2.1
    assert not explorer.finished(job)
    assert load_ros_map(tmp_path / "map.yaml").free.any()
    # the same frontier is not sold twice
    assert explorer.update(job).added == ()
    job.award(task.id, "robot-0", False)
    # the doorway turns out to be a wall: the frontier vanishes, and its task with it
    explorer.maps.hear("robot-0", patches(room(door=False), 2))
    change = explorer.update(job)
    assert change.gone == ((task.id, "robot-0"),) and job.tasks[task.id].state == GONE
    assert change.frontiers == 0 and explorer.finished(job)
    # a frontier no robot could reach goes too once it vanishes
    explorer.maps.hear("robot-0", patches(room(door=True), 3))
    (again,) = explorer.update(job).added
    job.tasks[again.id].state = UNREACHABLE
    assert not explorer.update(job).gone  # still there: left out
    explorer.maps.hear("robot-0", patches(room(door=False), 4))
    assert explorer.update(job).gone == ((again.id, None),) and not job.left_out()


def test_the_end_waits_for_every_robots_map():
    explorer = Explorer(CFG, MapPlanner(CFG), None)
    job = _job("robot-0", "robot-1")
    explorer.maps.hear("robot-0", patches(room(door=False), 1))
    explorer.update(job)
    assert not explorer.finished(job)  # robot-1 has sent nothing yet
    explorer.maps.hear("robot-1", patches(room(door=False), 1))
    explorer.update(job)
    assert explorer.finished(job)


def test_the_end_waits_until_each_robot_stands_on_mapped_floor():
    explorer = Explorer(CFG, MapPlanner(CFG), None)
    job = _job("robot-0")
    # the first scans: the room known, the robot's own surroundings not yet (no frontier is
    # reachable from it, and none counts as left)
    first = room(door=True)
    first[24:40, 24:40] = -1
    explorer.maps.hear("robot-0", patches(first, 1))
    change = explorer.update(job)
    assert change.frontiers == 0 and not explorer.finished(job)
    explorer.maps.hear("robot-0", patches(room(door=True), 2))
    assert explorer.update(job).frontiers == 1 and not explorer.finished(job)
    explorer.maps.hear("robot-0", patches(room(door=False), 3))
    explorer.update(job)
    assert explorer.finished(job)
    # once placed, a robot wedged where the map shows no floor holds nothing up
    job.robots["robot-0"].xy = (0.45, 0.45)
    explorer.update(job)
    assert explorer.finished(job)


def test_a_passage_a_robot_fits_through_stays_open_with_a_wall_cell_a_cell_off():
    """Two rooms joined by a corridor 9 free cells wide (a 0.5 m corridor as a 5 cm map draws
    it), one wall cell in it a cell off its wall: a robot fits through (0.175 m from the
    corridor's centre line to the stray cell's edge, the robot's radius 0.17 m), so the far
    room's open side is a frontier the robot can reach."""
    cells = np.full((64, 128), -1, dtype=np.int8)
    cells[8:56, 8:56] = 0
    cells[8, 8:56] = cells[55, 8:56] = cells[8:56, 8] = 100
    cells[8:56, 55] = 100
    cells[28:37, 55:96] = 0
    cells[27, 55:96] = cells[37, 55:96] = 100
    cells[36, 70] = 100
    cells[8:56, 95:120] = 0
    cells[8, 95:120] = cells[55, 95:120] = 100
    cells[8:56, 95] = 100
    cells[28:37, 95] = 0
    explorer = Explorer(CFG, MapPlanner(CFG), None)
    job = _job("robot-0")
    explorer.maps.hear("robot-0", patches(cells, 1))
    change = explorer.update(job)
    assert change.frontiers == 1, change.frontiers
    (task,) = change.added
    assert task.entry[0] > 95 * RES  # in the far room


def test_a_call_is_worth_less_near_a_goal_another_robot_is_headed_to(tmp_path: Path):
    explorer = Explorer(CFG, MapPlanner(CFG), None)
    job = _job("robot-0", "robot-1")
    explorer.maps.hear("robot-0", patches(room(door=True), 1))
    explorer.update(job)
    (tid,) = job.tasks
    alone = explorer.lots(job)[tid].gain_s
    assert alone == pytest.approx(
        CFG.coordinator.explore_gain_s_per_m2 * job.tasks[tid].task.area_m2
    )
    near = job.tasks[tid].task
    job.add_tasks((type(near)("f999", near.path + np.array([0.3, 0.0]), 1.0, 0.0, ()),))
    job.award("f999", "robot-1", False)
    assert 0 < explorer.lots(job)[tid].gain_s < alone


def test_the_exploring_market_sells_only_to_robots_without_work():
    job = _job("robot-0", "robot-1", "robot-2")
    journal = Journal(job, None, Keys("test"), lambda *_: None, 0.0)
    lock, wake, stop = threading.RLock(), threading.Event(), threading.Event()
    explorer = Explorer(CFG, MapPlanner(CFG), None)
    part = ExplorePart(explorer)
    market = Market(journal, None, None, lock, wake, stop, Parts([part]))  # type: ignore[arg-type]
    part.wire(SimpleNamespace(job=job, journal=journal))  # type: ignore[arg-type]
    explorer.maps.hear("robot-0", patches(room(door=True), 1))
    explorer.update(job)
    (tid,) = job.tasks
    lot = market._lots(())[tid]
    assert all(market._untried(lot, rid) for rid in ("robot-0", "robot-1", "robot-2"))
    job.award(tid, "robot-1", False)
    assert not market._untried(lot, "robot-1") and market._untried(lot, "robot-2")
    job.tasks[tid].tried = frozenset({"robot-2"})
    assert not market._untried(lot, "robot-2")
    assert job.tasks[tid].state == ASSIGNED and market._lots(()) == {}
    first, cut = market._regions()
    assert not first and cut() == ()
