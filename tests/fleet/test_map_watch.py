"""The coordinator's check of a stored map against the robots' maps as their patches bring
them, without a bus: a fleet whose robots mostly see another building refuses the map, one
robot alone does not, and the robots' maps of the stored floor agree with it."""

from types import SimpleNamespace

import numpy as np
from bus_stand_in import NoBus
from map_pieces import flat_segments, lidar_map, piece, route, segment_floor

from fleet.coordinator.map_watch import MapWatch
from fleet.floor_map import pack_grid
from fleet.params import load_fleet_config
from planners.map_check import AGREES, DIFFERS, UNDECIDED
from planners.map_merge import Transform2D

CFG = load_fleet_config()
FLAT = flat_segments()
OTHER = FLAT[:, ::-1].copy()  # the flat mirrored about its diagonal: walls elsewhere
BOUNDS = (-0.1, -0.1, 10.1, 10.1)
ROOM = route([(0.6, 0.5), (3.4, 0.5), (3.4, 2.4), (0.6, 2.4), (0.6, 3.9), (3.4, 3.9)])


def stored():
    everywhere = piece(
        segment_floor(FLAT), lambda xy: np.ones(xy.shape[:-1], bool), Transform2D.identity(), BOUNDS
    )
    return everywhere.to_gridmap(CFG.slam.occupied_threshold, CFG.slam.free_threshold)


def seen(segments, seed):
    m = lidar_map(segments, ROOM, Transform2D.identity(), seed)
    return m.to_gridmap(CFG.slam.occupied_threshold, CFG.slam.free_threshold)


def watch(*floors):
    w = MapWatch(NoBus(), stored(), "stored/map.yaml", CFG)  # type: ignore[arg-type]
    w.wire(SimpleNamespace(expected=3, keys=NoBus.keys))  # type: ignore[arg-type]
    for i, segments in enumerate(floors):
        w.maps.hear(f"robot-{i}", pack_grid(seen(segments, i)))
    return w


def test_the_robots_maps_of_the_stored_floor_agree():
    assert watch(FLAT, FLAT).check() == AGREES


def test_most_robots_seeing_another_building_refuse_the_map():
    w = watch(OTHER, OTHER, FLAT)
    assert w.check() == DIFFERS
    assert {rid: c.verdict for rid, c in w.checks.items()} == {
        "robot-0": DIFFERS,
        "robot-1": DIFFERS,
        "robot-2": AGREES,
    }


def test_one_robot_seeing_something_else_does_not_refuse_it():
    assert watch(OTHER).check() == UNDECIDED
