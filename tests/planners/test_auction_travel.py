"""Travel-time estimates for bids: Dijkstra on a coarsened grid, over a speed."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planners.auction import UNREACHABLE_FACTOR, TravelGrid, travel_times

RES = 0.025  # finer than the search's blocks: every test here goes through the coarsening
ORIGIN = (-1.0, -2.0)


def _room(width_m: float = 8.0, height_m: float = 6.0) -> np.ndarray:
    return np.ones((round(height_m / RES), round(width_m / RES)), dtype=bool)


def _xy(*pts) -> np.ndarray:
    """Points given in the room's frame (its lower left corner at 0, 0), in world metres."""
    return np.array(pts, dtype=float) + ORIGIN


def _p(x: float, y: float) -> np.ndarray:
    return _xy((x, y))[0]


def test_in_an_open_room_the_time_is_the_straight_line_over_the_speed():
    free = _room()
    start = _p(1.0, 1.0)
    targets = _xy((7.0, 1.0), (6.5, 5.2), (1.3, 4.0), (1.0, 1.0))
    got = travel_times(free, RES, ORIGIN, start, targets, 0.5)
    want = np.hypot(*(targets - start).T) / 0.5
    assert got == pytest.approx(want, abs=0.1 / 0.5)


def test_speed_scales_the_time():
    free = _room()
    start, targets = _p(1.0, 1.0), _xy((7.0, 5.0), (2.0, 3.0))
    slow = travel_times(free, RES, ORIGIN, start, targets, 0.25)
    fast = travel_times(free, RES, ORIGIN, start, targets, 1.0)
    assert slow == pytest.approx(4 * fast)


def _wall_with_door() -> np.ndarray:
    """A wall across the room at x ∈ [4, 4.2] m with a 0.8 m door at y ∈ [5, 5.8]."""
    free = _room()
    c = round(4.0 / RES)
    free[:, c : c + 8] = False
    free[round(5.0 / RES) : round(5.8 / RES), c : c + 8] = True
    return free


def test_a_wall_forces_the_detour_through_its_door():
    start, target = _p(2.0, 1.0), _p(6.0, 1.0)
    got = travel_times(_wall_with_door(), RES, ORIGIN, start, target[None, :], 1.0)[0]
    # the shortest way hugs the door's lower corners
    near, far = _p(4.0, 5.0), _p(4.2, 5.0)
    detour = math.dist(start, near) + math.dist(near, far) + math.dist(far, target)
    assert detour <= got <= 1.03 * detour + 0.1
    assert got > 1.5 * math.dist(start, target)


def test_an_unreachable_target_falls_back_to_a_penalized_straight_line():
    free = _room()
    # a sealed closet in the top right corner, and a thick block of obstacle in the middle
    free[round(4.0 / RES) : round(4.1 / RES), round(6.0 / RES) :] = False
    free[round(4.0 / RES) :, round(6.0 / RES) : round(6.1 / RES)] = False
    free[round(1.5 / RES) : round(3.5 / RES), round(3.0 / RES) : round(5.0 / RES)] = False
    start = _p(1.0, 1.0)
    targets = _xy((7.0, 5.0), (4.0, 2.5), (6.0, 1.0))
    got = travel_times(free, RES, ORIGIN, start, targets, 0.5)
    straight = np.hypot(*(targets - start).T) / 0.5
    assert got[:2] == pytest.approx(UNREACHABLE_FACTOR * straight[:2])
    assert got[2] == pytest.approx(straight[2], abs=0.2)


def test_a_target_just_inside_an_obstacle_is_priced_at_the_free_floor_beside_it():
    free = _wall_with_door()
    start = _p(2.0, 5.4)
    # 5 cm into the wall on the far side: coarsening closes the block it lies in
    target = _p(4.15, 2.0)
    got = travel_times(free, RES, ORIGIN, start, target[None, :], 1.0)[0]
    assert got < 2 * math.dist(start, target)


def test_a_start_outside_the_grid_or_in_a_wall_snaps_to_the_nearest_free_floor():
    free = _wall_with_door()
    target = _p(6.0, 1.0)[None, :]
    inside = travel_times(free, RES, ORIGIN, _p(3.8, 1.0), target, 1.0)[0]
    in_wall = travel_times(free, RES, ORIGIN, _p(4.03, 1.0), target, 1.0)[0]
    outside = travel_times(free, RES, ORIGIN, _p(-0.5, 1.0), target, 1.0)[0]
    assert in_wall == pytest.approx(inside, abs=0.3)
    assert np.isfinite(outside) and outside < UNREACHABLE_FACTOR * 6.5
    assert outside > inside


def test_a_travel_grid_answers_like_the_function_and_again_from_its_cache():
    free = _wall_with_door()
    grid = TravelGrid(free, RES, ORIGIN, 0.5)
    start, targets = _p(2.0, 1.0), _xy((6.0, 1.0), (7.5, 5.5), (0.5, 0.5))
    first = grid(start, targets)
    assert np.array_equal(grid(start, targets), first)
    assert np.array_equal(travel_times(free, RES, ORIGIN, start, targets, 0.5), first)


@pytest.mark.parametrize("speed", [0.0, -1.0])
def test_a_speed_that_is_not_positive_is_named(speed):
    with pytest.raises(ValueError, match="speed"):
        travel_times(_room(), RES, ORIGIN, _p(1, 1), _p(2, 2)[None, :], speed)


@pytest.mark.parametrize("shape", [(1, 1), (1, 5), (2, 2), (5, 1)])
def test_a_grid_narrower_than_a_step_is_priced_too(shape):
    """An exploring fleet's merged map starts a block wide: the steps that do not fit in it are
    no edges, and a target on it is priced as on any floor."""
    free = np.ones(shape, dtype=bool)
    start, target = np.array(ORIGIN), np.array(ORIGIN) + 0.01
    got = travel_times(free, 0.1, ORIGIN, start, target[None, :], 0.5)
    assert np.isfinite(got).all() and got[0] < 1.0
