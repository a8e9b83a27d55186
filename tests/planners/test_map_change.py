"""Finding furniture moved since the stored map was made, on synthetic maps: a box moved in
and a table taken away are found where they are; what SLAM's own error and the fleet's own
bodies put on a map of the unchanged floor (walls a cell off, a peer seen in one scan, specks,
cells never seen, floor exploring did not reach) is not a change."""

import math

import numpy as np
import pytest
from map_pieces import L_FREE, L_OCC, RES, box, flat_segments, lidar_map, route, segment_floor

from planners.grid import GridMap, clearance
from planners.map_change import (
    ADDED,
    REMOVED,
    MapChange,
    MapChangeParams,
    find_changes,
    obstacle_cells,
    with_cells,
)
from planners.map_merge import LogOddsMap, Transform2D

PARAMS = MapChangeParams()
FLAT = flat_segments()
IDENTITY = Transform2D.identity()
# round the living room (x < 4, y < 4.5) and its table (1.0–2.0, 1.0–1.6)
ROOM = route([(0.6, 0.5), (3.4, 0.5), (3.4, 2.4), (0.6, 2.4), (0.6, 3.9), (3.4, 3.9)])
# a chest moved into the living room
CHEST = (2.6, 3.0, 3.1, 3.4)
ONE_HIT = math.log(0.7 / 0.3)


def stored_map(segments=FLAT) -> GridMap:
    """The flat's floor at 5 cm, as a stored map: walls 10 cm thick, everything inside known."""
    floor = segment_floor(segments)
    rows, cols = 150, 210
    g = GridMap(np.zeros((rows, cols), bool), np.zeros((rows, cols), bool), RES, (-0.25, -0.25))
    occupied, observable = floor(g.cell_to_world(np.stack(np.mgrid[0:rows, 0:cols], -1)))
    return GridMap(occupied, ~observable, RES, g.origin)


def seen_map(segments=FLAT, poses=ROOM, seed=0) -> LogOddsMap:
    """What a robot's SLAM makes of ``segments`` driven along ``poses`` (world frame)."""
    return lidar_map(segments, poses, IDENTITY, seed)


def room_seen() -> LogOddsMap:
    """:func:`room_stored` as a robot's map holds it: the walls occupied, the floor free."""
    lo = np.where(room_stored().occupied, L_OCC, L_FREE).astype(np.float32)
    return LogOddsMap(lo, RES, (0.0, 0.0))


def room_stored() -> GridMap:
    """A 4 m × 3 m room, walls one cell thick on the grid's border: everything inside free."""
    occ = np.zeros((60, 80), bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    return GridMap(occ, np.zeros_like(occ), RES, (0.0, 0.0))


def test_the_unchanged_floor_shows_no_change() -> None:
    for seed in range(3):
        assert find_changes(seen_map(seed=seed), stored_map(), PARAMS, ROOM[:1, :2]) == ()


def test_a_box_moved_in_is_found_where_it_stands() -> None:
    moved = np.vstack([FLAT, np.array(box(*CHEST))])
    changes = find_changes(seen_map(moved), stored_map(), PARAMS, ROOM[-1:, :2])
    assert [c.kind for c in changes] == [ADDED], [c.describe() for c in changes]
    x0, y0, x1, y1 = changes[0].bounds
    # the faces seen: within a cell and a half of the box's (walls 10 cm thick round it)
    assert x0 >= CHEST[0] - 0.1 and y0 >= CHEST[1] - 0.1, changes[0].describe()
    assert x1 <= CHEST[2] + 0.1 and y1 <= CHEST[3] + 0.1, changes[0].describe()
    assert changes[0].size_m >= 0.4
    assert "at (" in changes[0].describe()


def test_a_table_taken_away_is_found_where_it_stood() -> None:
    table = box(1.0, 1.0, 2.0, 1.6)
    without = np.array([s for s in FLAT.tolist() if tuple(s) not in table])
    assert len(without) == len(FLAT) - 4
    changes = find_changes(seen_map(without), stored_map(), PARAMS)
    assert [c.kind for c in changes] == [REMOVED], [c.describe() for c in changes]
    cx, cy = changes[0].centre
    assert abs(cx - 1.5) < 0.1 and abs(cy - 1.3) < 0.1, changes[0].describe()


def test_walls_drawn_a_cell_off_are_no_change() -> None:
    # SLAM's walls one and two cells inside the stored map's, along the room's south and east
    lo = np.full((60, 80), L_FREE, np.float32)
    lo[0, :] = lo[-1, :] = lo[:, 0] = lo[:, -1] = L_OCC
    lo[1:3, 1:-1] = L_OCC
    lo[1:-1, -3:-1] = L_OCC
    seen = LogOddsMap(lo, RES, (0.0, 0.0))
    assert find_changes(seen, room_stored(), PARAMS) == ()
    # the same sliver in the middle of the floor is an obstacle the map does not have
    lo[30:32, 10:60] = L_OCC
    assert [c.kind for c in find_changes(seen, room_stored(), PARAMS)] == [ADDED]


def test_a_peer_seen_in_one_scan_is_no_change() -> None:
    seen = room_seen()
    centre = np.array([2.0, 1.5])
    xy = room_stored().cell_to_world(np.stack(np.mgrid[0:60, 0:80], -1))
    d = np.hypot(*(xy - centre).transpose(2, 0, 1))
    rim = (d > 0.15) & (d < 0.2) & (xy[..., 0] < centre[0])
    seen.log_odds[rim] = ONE_HIT
    assert find_changes(seen, room_stored(), PARAMS) == ()
    # seen for many scans: only where a robot stands is it no change
    seen.log_odds[rim] = L_OCC
    assert find_changes(seen, room_stored(), PARAMS, centre[None]) == ()
    assert [c.kind for c in find_changes(seen, room_stored(), PARAMS)] == [ADDED]


def test_a_face_seen_beside_a_robot_is_a_change() -> None:
    seen = room_seen()
    seen.log_odds[40, 20:30] = L_OCC  # a face 0.5 m long, y 2.0–2.05
    robot = np.array([[1.25, 2.25]])  # 0.2 m north of its middle
    assert [c.kind for c in find_changes(seen, room_stored(), PARAMS, robot)] == [ADDED]


def test_specks_and_cells_never_seen_are_no_change() -> None:
    seen = room_seen()
    seen.log_odds[20:22, 20:22] = L_OCC  # a 10 cm speck
    seen.log_odds[40:50, 40:70] = 0.0  # never observed
    assert find_changes(seen, room_stored(), PARAMS) == ()
    # cells the stored map holds occupied but nobody saw: no obstacle taken away
    stored = room_stored()
    stored.occupied[40:50, 40:70] = True
    assert find_changes(seen, stored, PARAMS) == ()


def test_a_stored_face_seen_free_along_its_length_is_no_obstacle_taken_away() -> None:
    # a table as an explored map has it: faces occupied, its inside unknown; the robots see
    # its south face's cells free (the true face halves them) and its other faces occupied
    stored = room_stored()
    stored.occupied[26:38, 40:56] = True
    seen = room_seen()
    seen.log_odds[26:38, 40:56] = 0.0
    seen.log_odds[26, 40:56] = L_FREE
    seen.log_odds[27:38, 40] = seen.log_odds[27:38, 55] = seen.log_odds[37, 40:56] = L_OCC
    assert find_changes(seen, stored, PARAMS) == ()
    # the whole table seen free: it was taken away
    seen.log_odds[26:38, 40:56] = L_FREE
    assert [c.kind for c in find_changes(seen, stored, PARAMS)] == [REMOVED]


def test_floor_exploring_did_not_reach_is_no_obstacle_taken_away() -> None:
    # the stored map left a corner unknown; the robots now see it free
    stored = room_stored()
    stored.unknown[40:59, 60:79] = True
    seen = room_seen()
    assert find_changes(seen, stored, PARAMS) == ()
    # with an obstacle the map had in it, that corner is furniture taken away
    stored.occupied[45:50, 65:70] = True
    stored.unknown[45:50, 65:70] = False
    assert [c.kind for c in find_changes(seen, stored, PARAMS)] == [REMOVED]


def test_an_outline_is_filled_and_cells_are_written_on_a_finer_grid() -> None:
    ring = [(x, y) for x in range(5) for y in range(4) if x in (0, 4) or y in (0, 3)]
    cells = np.array(ring, float) * RES + np.array([1.025, 1.025])
    filled, joined = obstacle_cells(MapChange(ADDED, cells, RES))
    assert len(filled) == 20 and len(cells) == 14 and joined == []
    fine = GridMap(np.zeros((120, 160), bool), np.ones((120, 160), bool), 0.025, (0.0, 0.0))
    out = with_cells(fine, filled, RES, occupied=True)
    assert out.occupied.sum() == 80 and not (out.occupied & out.unknown).any()
    rc = out.world_to_cell(np.array([[1.0, 1.0], [1.249, 1.199], [1.26, 1.1]]))
    assert out.occupied[rc[:, 0], rc[:, 1]].tolist() == [True, True, False]
    back = with_cells(out, filled, RES, occupied=False)
    assert not back.occupied.any() and back.free.sum() == 80


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("confidence", 0.5),
        ("confidence", 1.0),
        ("min_size_m", 0.0),
        ("wall_margin_m", -1.0),
        ("robot_clear_m", 0.0),
    ],
)
def test_bad_parameters_are_refused_naming_the_field(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        find_changes(room_seen(), room_stored(), MapChangeParams(**{field: value}))


def test_two_faces_span_their_box_and_a_face_seen_later_joins_it() -> None:
    south = np.array([(1.025 + 0.05 * i, 2.025) for i in range(10)])  # x 1.0–1.5, y 2.0–2.05
    west = np.array([(1.025, 2.075 + 0.05 * j) for j in range(7)])  # up to y 2.4
    box_, _ = obstacle_cells(MapChange(ADDED, np.vstack([south, west]), RES))
    assert len(box_) == 10 * 8
    # the east face seen later, 0.15 m from the south face put on the map before: one piece
    first, _ = obstacle_cells(MapChange(ADDED, south, RES))
    east = np.array([(1.475, 2.225 + 0.05 * j) for j in range(4)])
    whole, joined = obstacle_cells(MapChange(ADDED, east, RES), [first], join_m=0.2)
    assert joined == [0] and len(whole) == 10 * 8
    # a face farther off than join_m is a piece of its own
    alone, joined = obstacle_cells(MapChange(ADDED, east, RES), [first], join_m=0.1)
    assert joined == [] and len(alone) == 4


def test_the_far_face_of_a_piece_found_before_is_a_change_however_near_it() -> None:
    """The south part of a chest (x 1.05–1.55, y 2.0–2.3) is on the map already; its north face
    (y 2.35–2.40) is seen later, 0.1 m from it: a change, judged by the margin from the map as
    it was stored; by the margin from the map with the south part on it, it is lost."""
    stored = room_stored()
    south = stored.cell_to_world(np.argwhere(np.ones((6, 10), bool)) + np.array([40, 21]))
    on_map = with_cells(stored, south, RES, True)
    lo = room_seen().log_odds.copy()
    lo[40:46, 21:31] = L_OCC  # the part found before, seen still
    lo[47, 21:31] = L_OCC  # the north face
    seen = LogOddsMap(lo, RES, (0.0, 0.0))
    found = find_changes(seen, on_map, PARAMS, None, clearance(stored))
    assert [c.kind for c in found] == [ADDED], [c.describe() for c in found]
    x0, y0, x1, y1 = found[0].bounds
    assert (y0, y1) == pytest.approx((2.35, 2.40)) and (x0, x1) == pytest.approx((1.05, 1.55))
    assert find_changes(seen, on_map, PARAMS) == ()
