"""Correlative map matching: refining start poses, placing a map with an unknown start, and
refusing a placement that is not clear."""

import math

import numpy as np
import pytest
from map_pieces import (
    DATA,
    LIMITS,
    RES,
    box,
    flat_segments,
    free_iou,
    grid_floor,
    lidar_map,
    piece,
    route,
    segment_floor,
    truth_on,
)

from planners.map_match import MatchParams, place_map, refine_transform, refine_transforms
from planners.map_merge import LogOddsMap, Transform2D, merge_maps

PARAMS = MatchParams()
FLOOR = segment_floor(flat_segments())
BOUNDS = (-0.1, -0.1, 10.1, 7.1)
B_TO_A = Transform2D(0.37, -0.21, math.radians(7.0))
IDENTITY = Transform2D.identity()


def grid(m: LogOddsMap):
    return m.to_gridmap(PARAMS.occupied_threshold, PARAMS.free_threshold)


def left(x: float):
    return lambda xy: xy[..., 0] < x


def right(x: float):
    return lambda xy: xy[..., 0] > x


def assert_close(found: Transform2D, truth: Transform2D) -> None:
    """Within one cell and one degree."""
    assert abs(found.x - truth.x) <= RES and abs(found.y - truth.y) <= RES, (found, truth)
    assert abs(math.degrees(found.theta - truth.theta)) <= 1.0, (found, truth)


def halves(overlap_from: float = 4.0, overlap_to: float = 6.0):
    a = piece(FLOOR, left(overlap_to), IDENTITY, BOUNDS)
    b = piece(FLOOR, right(overlap_from), B_TO_A, BOUNDS)
    return a, b


def test_a_map_with_an_unknown_start_is_placed_within_a_cell_and_a_degree():
    a, b = halves()
    match = place_map(grid(b), grid(a), PARAMS)
    assert match.confident, match.reason
    assert_close(match.transform, B_TO_A)
    assert match.overlap_m2 > 10.0 and match.ambiguity < PARAMS.max_ambiguity
    # the walls agree well, but not as well as a stricter threshold asks
    strict = MatchParams(min_score=min(match.score + 0.01, 1.0))
    refused = place_map(grid(b), grid(a), strict)
    assert not refused.confident and refused.reason.startswith("score"), refused.reason


def test_a_prior_off_by_30_cm_and_5_degrees_is_corrected():
    a, b = halves()
    prior = Transform2D(B_TO_A.x + 0.3, B_TO_A.y, B_TO_A.theta - math.radians(5.0))
    match = refine_transform(grid(b), grid(a), prior, PARAMS)
    assert match.confident, match.reason
    assert_close(match.transform, B_TO_A)
    # a window too small to hold the truth cannot reach it
    narrow = MatchParams(window_xy=0.1, window_theta_deg=2.0)
    off = refine_transform(grid(b), grid(a), prior, narrow).transform
    assert abs(off.x - B_TO_A.x) > RES or abs(off.theta - B_TO_A.theta) > math.radians(1.0)


def test_maps_a_lidar_made_in_two_frames_are_placed_and_refined():
    segments = flat_segments()
    a = lidar_map(
        segments, route([(1, 3), (3, 3), (3, 1.5), (3, 3), (5, 3), (5.5, 2)]), IDENTITY, 0
    )
    b = lidar_map(
        segments, route([(9, 2), (8.7, 4), (7.5, 3.5), (5.5, 3.2), (5.5, 4.5)]), B_TO_A, 1
    )
    placed = place_map(grid(b), grid(a), PARAMS)
    assert placed.confident, placed.reason
    assert_close(placed.transform, B_TO_A)
    prior = Transform2D(B_TO_A.x + 0.3, B_TO_A.y, B_TO_A.theta - math.radians(5.0))
    refined = refine_transform(grid(b), grid(a), prior, PARAMS)
    assert refined.confident, refined.reason
    assert_close(refined.transform, B_TO_A)


def test_three_robots_drifted_start_poses_are_refined_around_the_anchor():
    c_to_a = Transform2D(-0.5, 0.8, math.radians(-12.0))
    maps = [
        piece(FLOOR, left(6.0), IDENTITY, BOUNDS),
        piece(FLOOR, right(4.0), B_TO_A, BOUNDS),
        piece(FLOOR, lambda xy: xy[..., 1] > 3.0, c_to_a, BOUNDS),
    ]
    priors = [
        IDENTITY,
        Transform2D(B_TO_A.x + 0.2, B_TO_A.y - 0.2, B_TO_A.theta + math.radians(4.0)),
        Transform2D(c_to_a.x - 0.25, c_to_a.y + 0.15, c_to_a.theta - math.radians(5.0)),
    ]
    matches = refine_transforms(maps, priors, LIMITS, PARAMS)
    assert matches[0].transform == IDENTITY
    assert all(m.confident for m in matches), [m.reason for m in matches]
    assert_close(matches[1].transform, B_TO_A)
    assert_close(matches[2].transform, c_to_a)
    merged = merge_maps(maps, [m.transform for m in matches], LIMITS)
    assert free_iou(grid(merged), truth_on(FLOOR, merged)) > 0.97


def test_a_map_of_another_place_is_refused():
    a, _ = halves()
    other = np.array(
        [
            *box(0, 0, 8, 6),
            (3, 0, 3, 4),
            (3, 5, 3, 6),
            (5, 2, 8, 2),
            (5, 2, 5, 3.5),
            *box(6, 4, 7, 5),
            *box(1, 1, 1.5, 3),
        ]
    )
    stranger = piece(segment_floor(other), right(-1.0), B_TO_A, (-0.1, -0.1, 8.1, 6.1))
    match = place_map(grid(stranger), grid(a), PARAMS)
    assert not match.confident and match.reason != "matched"
    # nor is it placed near a start pose given for it
    near = refine_transform(grid(stranger), grid(a), B_TO_A, PARAMS)
    assert not near.confident and near.reason != "matched"


def test_a_map_of_a_symmetric_room_is_refused_as_ambiguous():
    room = segment_floor(np.array(box(0.0, 0.0, 6.0, 4.0)))
    bounds = (-0.1, -0.1, 6.1, 4.1)
    a = piece(room, left(4.5), IDENTITY, bounds)
    b = piece(room, right(1.5), B_TO_A, bounds)
    match = place_map(grid(b), grid(a), PARAMS)
    assert not match.confident
    assert match.reason.startswith("ambiguous") and match.runner_up is not None
    # the room turned half round is the runner-up or the best
    turns = sorted(abs(math.degrees(t.theta)) for t in (match.transform, match.runner_up))
    assert turns[0] == pytest.approx(7.0, abs=1.0) and turns[1] == pytest.approx(173.0, abs=1.0)


def test_a_map_that_overlaps_by_a_strip_is_refused():
    a, b = halves(overlap_from=5.7)  # 0.3 m × 7 m seen by both
    match = place_map(grid(b), grid(a), PARAMS)
    assert not match.confident and match.reason != "matched"


def test_the_recorded_apartment_cut_in_two_is_placed_refined_and_merged_back():
    path = DATA / "cob_ipa_apartment.yaml"
    if not path.exists():
        pytest.skip(f"{path} is absent (shared data not checked out)")
    from fleet.world import load_ros_map

    floor_grid = load_ros_map(path)
    floor = grid_floor(floor_grid)
    seen = np.argwhere(~floor_grid.unknown)
    (x0, y0), (x1, y1) = (
        floor_grid.cell_to_world(seen.min(axis=0)),
        floor_grid.cell_to_world(seen.max(axis=0)),
    )
    bounds = (x0 - RES, y0 - RES, x1 + RES, y1 + RES)
    mid = (x0 + x1) / 2
    a = piece(floor, left(mid + 1.5), IDENTITY, bounds)  # a 3 m wide strip seen by both
    b = piece(floor, right(mid - 1.5), B_TO_A, bounds)
    placed = place_map(grid(b), grid(a), PARAMS)
    assert placed.confident, placed.reason
    assert_close(placed.transform, B_TO_A)
    prior = Transform2D(B_TO_A.x - 0.2, B_TO_A.y + 0.2, B_TO_A.theta + math.radians(5.0))
    refined = refine_transform(grid(b), grid(a), prior, PARAMS)
    assert refined.confident, refined.reason
    assert_close(refined.transform, B_TO_A)
    merged = merge_maps([a, b], [IDENTITY, refined.transform], LIMITS)
    assert free_iou(grid(merged), truth_on(floor, merged)) > 0.97
