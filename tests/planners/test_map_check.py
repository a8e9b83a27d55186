"""Telling a stored map of the robots' own floor from one of another building, on synthetic
maps: a robot's map of the floor agrees, one of another flat or of the same flat drawn in
another frame differs, one that has seen too little is not judged, and one robot alone does
not decide for a fleet."""

import math

import numpy as np
from map_pieces import flat_segments, lidar_map, piece, route, segment_floor

from planners.map_check import (
    AGREES,
    DIFFERS,
    UNDECIDED,
    MapCheck,
    MapCheckParams,
    check_map,
    fleet_verdict,
)
from planners.map_match import MatchParams
from planners.map_merge import Transform2D

PARAMS = MapCheckParams()
M = PARAMS.match
FLAT = flat_segments()
BOUNDS = (-0.1, -0.1, 10.1, 7.1)
IDENTITY = Transform2D.identity()
# the living room of the flat (x < 4, y < 4.5), driven round its table
ROOM = route([(0.6, 0.5), (3.4, 0.5), (3.4, 2.4), (0.6, 2.4), (0.6, 3.9), (3.4, 3.9)])


def grid(m):
    return m.to_gridmap(M.occupied_threshold, M.free_threshold)


def stored(segments=FLAT, to_floor=IDENTITY):
    """The whole floor of ``segments`` as a stored map, drawn in the frame ``to_floor``."""
    return grid(
        piece(segment_floor(segments), lambda xy: np.ones(xy.shape[:-1], bool), to_floor, BOUNDS)
    )


def robot_map(poses=ROOM, seed=0):
    """What a robot's SLAM makes of the flat's living room, in the world's frame."""
    return grid(lidar_map(FLAT, poses, IDENTITY, seed))


def other_building():
    """Another flat of the same size: its rooms cut elsewhere, its furniture elsewhere."""
    walls = [
        (0.0, 0.0, 10.0, 0.0),
        (10.0, 0.0, 10.0, 7.0),
        (10.0, 7.0, 0.0, 7.0),
        (0.0, 7.0, 0.0, 0.0),
        (0.0, 3.0, 2.0, 3.0),
        (3.0, 3.0, 6.0, 3.0),
        (6.0, 0.0, 6.0, 1.8),
        (6.0, 2.8, 6.0, 7.0),
        (2.5, 3.0, 2.5, 7.0),
    ]
    furniture = [
        (4.0, 1.0, 5.0, 1.0),
        (5.0, 1.0, 5.0, 2.0),
        (5.0, 2.0, 4.0, 2.0),
        (4.0, 2.0, 4.0, 1.0),
    ]
    return np.array(walls + furniture)


def test_a_robots_map_of_the_stored_floor_agrees():
    check = check_map(robot_map(), stored(), PARAMS)
    assert check.verdict == AGREES, check


def test_a_robots_map_with_a_few_centimetres_of_drift_still_agrees():
    drifted = grid(lidar_map(FLAT, ROOM, Transform2D(0.04, -0.03, math.radians(1.0)), 1))
    check = check_map(drifted, stored(), PARAMS)
    assert check.verdict == AGREES, check


def test_the_map_of_another_building_differs():
    check = check_map(robot_map(), stored(other_building()), PARAMS)
    assert check.verdict == DIFFERS, check
    assert "do not line up" in check.reason


def test_the_same_floor_drawn_in_another_frame_differs():
    shifted = stored(to_floor=Transform2D(0.45, 0.0, 0.0))
    check = check_map(robot_map(), shifted, PARAMS)
    assert check.verdict == DIFFERS, check


def test_a_map_that_has_seen_too_little_is_not_judged():
    glimpse = robot_map(route([(0.6, 0.5), (0.7, 0.5)]))
    params = MapCheckParams(MatchParams(min_overlap_m2=40.0))
    check = check_map(glimpse, stored(other_building()), params)
    assert check.verdict == UNDECIDED, check


def _check(verdict: str) -> MapCheck:
    return MapCheck(verdict, 0.0, 0.0, IDENTITY, "")


def test_one_robot_alone_does_not_decide_for_the_fleet():
    assert fleet_verdict([_check(DIFFERS), _check(UNDECIDED)], 3) == UNDECIDED
    assert fleet_verdict([_check(DIFFERS), _check(AGREES)], 2) == UNDECIDED
    assert fleet_verdict([_check(DIFFERS), _check(DIFFERS), _check(AGREES)], 3) == DIFFERS
    assert fleet_verdict([_check(AGREES), _check(AGREES)], 3) == AGREES
    assert fleet_verdict([_check(DIFFERS)], 1) == DIFFERS
