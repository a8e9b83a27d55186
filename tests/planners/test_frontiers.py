"""Frontier extraction on hand-made grids, and the coordination discount."""

import math

import numpy as np
import pytest
from robots import ROBOT

from planners.frontiers import discounted_utility, find_frontiers, information_gain, placed
from planners.grid import GridMap

RES = 0.05
RANGE = 6.0


def room_in_the_unknown(rows: int = 160, cols: int = 160) -> tuple[np.ndarray, np.ndarray]:
    """A 3 m × 3 m walled room (cells 20..79) seen whole, everything around it unknown."""
    occupied = np.zeros((rows, cols), dtype=bool)
    unknown = np.ones((rows, cols), dtype=bool)
    unknown[20:80, 20:80] = False
    occupied[20, 20:80] = occupied[79, 20:80] = True
    occupied[20:80, 20] = occupied[20:80, 79] = True
    return occupied, unknown


def door(occupied: np.ndarray, rows: slice, col: int) -> None:
    """An opening in the wall at ``col``: the doorway cells were seen free."""
    occupied[rows, col] = False


def grid(occupied: np.ndarray, unknown: np.ndarray) -> GridMap:
    return GridMap(occupied, unknown, RES, (0.0, 0.0))


ROBOT_AT = np.array([[2.5, 2.5]])  # cell (50, 50), the room's middle


def test_a_room_with_one_opening_has_one_frontier_at_the_opening():
    occ, unk = room_in_the_unknown()
    door(occ, slice(40, 52), 79)  # 0.6 m wide
    (f,) = find_frontiers(grid(occ, unk), ROBOT_AT, ROBOT.radius, RANGE)
    assert set(map(tuple, f.cells.tolist())) == {(r, 79) for r in range(40, 52)}
    assert math.isclose(f.size, 12 * RES)
    assert f.centroid == pytest.approx((79.5 * RES, 46.0 * RES))
    # the goal is a doorway cell nearest the centroid (rows 45 and 46 tie)
    assert f.goal[0] == 79.5 * RES and f.goal[1] in (45.5 * RES, 46.5 * RES)
    assert f.information_gain > 10.0


def test_an_opening_narrower_than_the_robot_is_no_frontier():
    occ, unk = room_in_the_unknown()
    door(occ, slice(40, 46), 79)  # 0.30 m < the robot's 0.34 m
    assert find_frontiers(grid(occ, unk), ROBOT_AT, ROBOT.radius, RANGE) == ()


def test_a_long_frontier_beyond_a_gap_narrower_than_the_robot_is_unreachable():
    occ, unk = room_in_the_unknown()
    # a passage 0.3 m wide out through the right wall, 2 m long; its far side never seen, so
    # its whole length is a frontier, but no robot centre gets through the gap in the wall
    door(occ, slice(40, 46), 79)
    unk[39:46, 80:120] = False
    occ[39, 79:120] = True
    g = grid(occ, unk)
    assert find_frontiers(g, ROBOT_AT, ROBOT.radius, RANGE) == ()
    # a robot that fits through the gap finds it
    (f,) = find_frontiers(g, ROBOT_AT, 0.1, RANGE)
    assert len(f.cells) > 40


def test_a_frontier_behind_a_wall_is_unreachable():
    occ, unk = room_in_the_unknown()
    # a second room right of the first, seen (through a window, say) but with no way in from
    # the robot's room; its far wall opens onto the unknown
    unk[20:80, 80:140] = False
    occ[20, 80:140] = occ[79, 80:140] = True
    occ[20:80, 139] = True
    door(occ, slice(40, 60), 139)
    g = grid(occ, unk)
    assert find_frontiers(g, ROBOT_AT, ROBOT.radius, RANGE) == ()
    # the same frontier from inside the second room
    (f,) = find_frontiers(g, np.array([[5.5, 2.5]]), ROBOT.radius, RANGE)
    assert {c for _, c in f.cells.tolist()} == {139}


def test_a_frontier_smaller_than_the_robot_is_dropped():
    occ, unk = room_in_the_unknown()
    unk[50, 50] = True  # one cell of the floor never seen: its ring of 8 frontier cells
    g = grid(occ, unk)
    at = np.array([[1.5, 1.5]])
    (f,) = find_frontiers(g, at, 0.15, RANGE)  # 8 cells ≥ 0.30 m / 0.05 m
    assert len(f.cells) == 8
    assert find_frontiers(g, at, 0.25, RANGE) == ()  # 8 cells < 0.50 m / 0.05 m


def test_the_frontier_facing_more_unknown_gains_more():
    occ, unk = room_in_the_unknown()
    # a closet beyond the left wall, 19 × 29 cells unseen inside, its door open
    occ[30, 0:21] = occ[60, 0:21] = True
    occ[30:61, 0] = True
    unk[30:61, 0:21] = ~occ[30:61, 0:21]
    door(occ, slice(35, 55), 20)
    (closet,) = find_frontiers(grid(occ, unk), ROBOT_AT, ROBOT.radius, RANGE)
    assert math.isclose(closet.information_gain, 19 * 29 * RES**2, rel_tol=0.02)
    # an opening on the right onto the open unknown; its rays through the room and out of the
    # right opening now add to the closet door's gain too
    door(occ, slice(35, 55), 79)
    frontiers = find_frontiers(grid(occ, unk), ROBOT_AT, ROBOT.radius, RANGE)
    assert len(frontiers) == 2
    big, small = frontiers  # sorted by gain
    assert big.goal[0] > 3.5 and small.goal[0] < 1.5
    assert big.information_gain > 5 * small.information_gain


def test_a_robot_is_placed_only_on_floor_a_robot_centre_can_be_on():
    occ, unk = room_in_the_unknown()
    robots = np.array([[2.5, 2.5], [1.1, 2.5], [6.0, 6.0], [-1.0, 2.5]])
    # the room's middle; beside the wall, within its radius of floor it fits on; in the
    # unknown; off the grid
    assert placed(grid(occ, unk), robots, ROBOT.radius).tolist() == [True, True, False, False]
    unk[45:56, 45:56] = True  # the middle not yet seen
    assert placed(grid(occ, unk), robots[:1], ROBOT.radius).tolist() == [False]
    assert find_frontiers(grid(occ, unk), robots[:1], ROBOT.radius, RANGE) == ()


def test_information_gain_of_an_open_disc_is_its_area_and_walls_block_it():
    unk = np.ones((400, 400), dtype=bool)
    unk[195:205, 195:205] = False
    occ = np.zeros_like(unk)
    g = grid(occ, unk)
    centre = np.array([[10.0, 10.0]])
    (gain,) = information_gain(g, centre, 3.0)
    assert math.isclose(gain, math.pi * 3.0**2 - 100 * RES**2, rel_tol=0.03)
    occ[:, 210] = True  # a wall 0.5 m to the right hides the disc's right part
    (blocked,) = information_gain(grid(occ, unk), centre, 3.0)
    assert blocked < 0.7 * gain


def test_burgard_discount_falls_linearly_with_distance_to_assigned_goals():
    goals = np.array([[0.0, 0.0], [3.0, 0.0], [10.0, 0.0]])
    u = np.array([2.0, 2.0, 2.0])
    out = discounted_utility(u, goals, np.array([[0.0, 0.0]]), sensor_range=6.0)
    np.testing.assert_allclose(out, [0.0, 1.0, 2.0])
    # two assigned goals nearby add up and floor at zero
    two = discounted_utility(u, goals, np.array([[3.0, 1.0], [3.0, -1.0]]), sensor_range=6.0)
    p = 1.0 - math.hypot(0.0, 1.0) / 6.0
    assert two[1] == max(0.0, 2.0 * (1.0 - 2 * p))
    np.testing.assert_allclose(discounted_utility(u, goals, np.empty((0, 2)), 6.0), u)
