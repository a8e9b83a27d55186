"""Lidar ray casting against analytic geometry, the brute-force reference, and occupancy grids."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from fleet.bench.lidar import furnished_scene, map_scene
from fleet.cli import app
from fleet.world import load_ros_map
from sim_server.lidar import (
    SegmentIndex,
    add_noise,
    cast_scans,
    cast_scans_reference,
    occupancy_to_segments,
    polygon_edges,
)

BEAMS = np.linspace(0.0, 2 * math.pi, 360, endpoint=False)
NO_DISCS = np.zeros((0, 3))
RADIUS = 0.17


def rotated_box(cx: float, cy: float, w: float, h: float, angle: float) -> np.ndarray:
    """The 4 edges of a w × h rectangle centred at (cx, cy), rotated by angle."""
    local = np.array([[-w / 2, -h / 2], [w / 2, -h / 2], [w / 2, h / 2], [-w / 2, h / 2]])
    c, s = math.cos(angle), math.sin(angle)
    corners = local @ np.array([[c, s], [-s, c]]) + [cx, cy]
    return np.hstack([corners, np.roll(corners, -1, axis=0)])


def box_exit_distance(p_local: np.ndarray, d_local: np.ndarray, w: float, h: float) -> np.ndarray:
    """Distance from a point inside an axis-aligned w × h box centred at 0 to its boundary."""
    with np.errstate(divide="ignore"):
        tx = np.where(
            d_local[:, 0] != 0,
            (np.sign(d_local[:, 0]) * w / 2 - p_local[0]) / d_local[:, 0],
            np.inf,
        )
        ty = np.where(
            d_local[:, 1] != 0,
            (np.sign(d_local[:, 1]) * h / 2 - p_local[1]) / d_local[:, 1],
            np.inf,
        )
    return np.minimum(tx, ty)


ROOM = dict(cx=2.0, cy=-1.0, w=5.0, h=3.5, angle=0.37)


def room_truth(origin: np.ndarray, heading: float) -> np.ndarray:
    """Analytic ranges from origin to the walls of ROOM, computed in the room's own frame."""
    c, s = math.cos(-ROOM["angle"]), math.sin(-ROOM["angle"])
    rot = np.array([[c, -s], [s, c]])
    p_local = rot @ (origin - [ROOM["cx"], ROOM["cy"]])
    angles = heading - ROOM["angle"] + BEAMS
    d_local = np.column_stack([np.cos(angles), np.sin(angles)])
    return box_exit_distance(p_local, d_local, ROOM["w"], ROOM["h"])


def test_square_room_every_beam_matches_the_analytic_wall_distance():
    walls = rotated_box(**ROOM)
    origin = np.array([3.1, -0.4])
    heading = 2.2
    ranges = cast_scans(origin[None], [heading], BEAMS, walls, NO_DISCS, range_max=20.0)[0]
    np.testing.assert_allclose(ranges, room_truth(origin, heading), rtol=0, atol=1e-9)


def test_beams_beyond_range_max_read_inf_and_the_rest_stay_exact():
    walls = rotated_box(**ROOM)
    origin = np.array([0.5, -1.2])
    truth = room_truth(origin, 0.0)
    range_max = 2.5
    ranges = cast_scans(origin[None], [0.0], BEAMS, walls, NO_DISCS, range_max)[0]
    far = truth > range_max
    assert far.any() and (~far).any()
    assert np.all(np.isinf(ranges[far]))
    np.testing.assert_allclose(ranges[~far], truth[~far], rtol=0, atol=1e-9)


def test_another_robot_is_seen_with_the_exact_ray_circle_distance_and_hides_nothing_else():
    walls = rotated_box(**ROOM)
    me, other, radius = np.array([1.0, -1.5]), np.array([2.3, -0.9]), 0.17
    heading = -0.8
    discs = np.array([[*me, radius], [*other, radius]])
    ranges = cast_scans(me[None], [heading], BEAMS, walls, discs, 20.0, self_index=[0])[0]

    angles = heading + BEAMS
    d = np.column_stack([np.cos(angles), np.sin(angles)])
    m = other - me
    along = d @ m
    off = d[:, 0] * m[1] - d[:, 1] * m[0]
    hits = (np.abs(off) <= radius) & (along > 0)
    circle = along - np.sqrt(np.maximum(radius**2 - off**2, 0.0))
    expected = np.where(hits, circle, room_truth(me, heading))
    np.testing.assert_allclose(ranges, expected, rtol=0, atol=1e-9)
    subtended = 2 * math.asin(radius / np.linalg.norm(m))
    assert abs(hits.sum() - subtended / (2 * math.pi / 360)) <= 1
    assert hits.sum() >= 5


def test_own_disc_is_invisible_but_a_disc_around_the_sensor_blocks_it():
    walls = rotated_box(**ROOM)
    me = np.array([[2.0, -1.0]])
    own = np.array([[2.0, -1.0, 0.17]])
    alone = cast_scans(me, [0.3], BEAMS, walls, NO_DISCS, 20.0)
    np.testing.assert_array_equal(cast_scans(me, [0.3], BEAMS, walls, own, 20.0, [0]), alone)
    np.testing.assert_array_equal(cast_scans(me, [0.3], BEAMS, walls, own, 20.0, [-1]), 0.0)


def test_several_robots_scan_each_other_in_one_call_like_one_at_a_time():
    walls = rotated_box(**ROOM)
    origins = np.array([[0.5, -1.5], [2.0, -0.5], [3.5, -1.2]])
    headings = np.array([0.1, 2.0, -2.5])
    discs = np.column_stack([origins, np.full(3, 0.17)])
    together = cast_scans(origins, headings, BEAMS, walls, discs, 6.0, np.arange(3))
    for i in range(3):
        alone = cast_scans(origins[i : i + 1], headings[i : i + 1], BEAMS, walls, discs, 6.0, [i])
        np.testing.assert_array_equal(together[i], alone[0])
    assert np.all(together < 6.0)


@pytest.mark.parametrize("seed", range(3))
def test_rays_aimed_at_a_shared_corner_never_leak_through(seed):
    rng = np.random.default_rng(seed)
    phis = rng.uniform(-math.pi, math.pi, 100)
    for phi in phis:
        u = np.array([math.cos(phi), math.sin(phi)])
        n = np.array([-u[1], u[0]])
        apex = 2.0 * u
        # A wedge opening away from the sensor, its apex on the beam, and a wall behind it.
        wedge = np.array([[*(apex + u + n), *apex], [*apex, *(apex + u - n)]])
        backstop = np.array([[*(5 * u + 3 * n), *(5 * u - 3 * n)]])
        segments = np.vstack([wedge, backstop])
        r = cast_scans([[0.0, 0.0]], [phi], [0.0], segments, NO_DISCS, 10.0)
        assert abs(r[0, 0] - 2.0) <= 1e-9


def test_corner_endpoint_parallel_and_behind_cases():
    origin = [[0.0, 0.0]]
    # A square's corner straight ahead at 45°.
    square = rotated_box(1.5, 1.5, 1.0, 1.0, 0.0)
    r = cast_scans(origin, [math.pi / 4], [0.0], square, NO_DISCS, 10.0)
    assert abs(r[0, 0] - math.sqrt(2)) <= 1e-9
    # A segment whose endpoint lies on the beam.
    r = cast_scans(origin, [0.0], [0.0], [[2.0, 0.0, 2.0, 1.0]], NO_DISCS, 10.0)
    assert abs(r[0, 0] - 2.0) <= 1e-12
    # A beam running along a segment sees its near end; a parallel offset one sees nothing.
    r = cast_scans(origin, [0.0], [0.0, math.pi], [[1.0, 0.0, 3.0, 0.0]], NO_DISCS, 10.0)
    assert r[0, 0] == pytest.approx(1.0, abs=1e-12) and np.isinf(r[0, 1])
    r = cast_scans(origin, [0.0], [0.0], [[1.0, 0.5, 3.0, 0.5]], NO_DISCS, 10.0)
    assert np.isinf(r[0, 0])
    # A sensor on a segment is blocked.
    r = cast_scans([[2.0, 0.0]], [0.0], BEAMS, [[1.0, 0.0, 3.0, 0.0]], NO_DISCS, 10.0)
    np.testing.assert_array_equal(r, 0.0)
    # Zero-length segments are ignored, segments behind the sensor are not seen.
    r = cast_scans(origin, [0.0], [0.0], [[1.0, 0.0, 1.0, 0.0], [-1, -1, -1, 1]], NO_DISCS, 10.0)
    assert np.isinf(r[0, 0])


@pytest.mark.parametrize("beams", [BEAMS, np.linspace(-2.0, 2.0, 271), np.array([3.0, -1.0, 0.5])])
def test_matches_brute_force_reference_on_a_furnished_scene(beams):
    scene = furnished_scene(400, 12, RADIUS, seed=4)
    args = (scene.origins, scene.headings, beams)
    rest = (scene.discs, 6.0, scene.self_index)
    expected = cast_scans_reference(*args, scene.segments, *rest)
    fast = cast_scans(*args, scene.segments, *rest)
    indexed = cast_scans(*args, SegmentIndex(scene.segments, cell=0.7, reach=6.0), *rest)
    finite = np.isfinite(expected)
    assert finite.mean() > 0.5
    for got in (fast, indexed):
        np.testing.assert_array_equal(np.isfinite(got), finite)
        np.testing.assert_allclose(got[finite], expected[finite], rtol=0, atol=1e-9)


def _overlapping_boxes(seed: int) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """Rotated boxes (every other one clockwise, some overlapping, walls made of thick boxes)
    and sensors outside all of them."""
    rng = np.random.default_rng(seed)
    walls = [(3.0, 0.0, 6.2, 0.2, 0.0), (3.0, 5.0, 6.2, 0.2, 0.0)]
    walls += [(0.0, 2.5, 0.2, 5.2, 0.0), (6.0, 2.5, 0.2, 5.2, 0.0)]
    furniture = rng.uniform([0.5, 0.5, 0.2, 0.2, 0.0], [5.5, 4.5, 1.2, 0.8, 3.0], (14, 5))
    polys = [rotated_box(*b)[:, :2] for b in [*walls, *furniture]]
    polys = [p if i % 2 else p[::-1] for i, p in enumerate(polys)]
    origins = []
    while len(origins) < 40:
        q = rng.uniform([0.2, 0.2], [5.8, 4.8])
        if not any(_inside_convex(q, p) for p in polys):
            origins.append(q)
    return polys, np.array(origins), rng.uniform(-math.pi, math.pi, 40)


def _inside_convex(q: np.ndarray, poly: np.ndarray) -> bool:
    e = np.roll(poly, -1, axis=0) - poly
    w = q - poly
    cross = e[:, 0] * w[:, 1] - e[:, 1] * w[:, 0]
    return bool(np.all(cross > -1e-6) or np.all(cross < 1e-6))


@pytest.mark.parametrize("seed", range(3))
def test_one_sided_polygon_edges_give_the_same_ranges_as_two_sided(seed):
    polys, origins, headings = _overlapping_boxes(seed)
    edges = polygon_edges(polys)
    discs = np.column_stack([origins[:5], np.full(5, 0.17)])
    args = (origins, headings, BEAMS)
    rest = (discs, 6.0, np.r_[np.arange(5), np.full(35, -1)])
    two_sided = cast_scans(*args, edges, *rest)
    assert np.isfinite(two_sided).mean() > 0.9
    for segments in (edges, SegmentIndex(edges, cell=0.7, reach=6.0)):
        np.testing.assert_array_equal(cast_scans(*args, segments, *rest, one_sided=True), two_sided)
    # Edges turned clockwise show their inner side: one-sided casting then sees through walls.
    clockwise = polygon_edges(polys)[:, [2, 3, 0, 1]]
    assert not np.array_equal(cast_scans(*args, clockwise, *rest, one_sided=True), two_sided)


def test_polygon_edges_turn_every_polygon_counter_clockwise():
    square = np.array([[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]])  # clockwise
    edges = polygon_edges([square, square[::-1] + 2.0])
    assert edges.shape == (8, 4)
    ux, uy = edges[:, 2] - edges[:, 0], edges[:, 3] - edges[:, 1]
    mx, my = (edges[:, 0] + edges[:, 2]) / 2, (edges[:, 1] + edges[:, 3]) / 2
    centre = np.repeat([[0.5, 0.5], [2.5, 2.5]], 4, axis=0)
    # The centre is on the left of every edge.
    assert np.all(ux * (centre[:, 1] - my) - uy * (centre[:, 0] - mx) > 0)
    assert polygon_edges([]).shape == (0, 4)


def test_segment_index_rejects_a_reach_shorter_than_the_range():
    index = SegmentIndex(rotated_box(**ROOM), reach=4.0)
    with pytest.raises(ValueError, match="reach"):
        cast_scans([[2.0, -1.0]], [0.0], BEAMS, index, NO_DISCS, 6.0)


def test_noise_has_the_configured_sigma_and_range_limits():
    rng = np.random.default_rng(7)
    sigma, range_min, range_max = 0.01, 0.1, 6.0
    n = 200_000
    mid = add_noise(np.full(n, 3.0), sigma, range_min, range_max, rng)
    assert abs(mid.mean() - 3.0) < 4 * sigma / math.sqrt(n)
    assert abs(mid.std() / sigma - 1) < 0.01
    # One sigma inside range_max: about 15.9 % of readings fall beyond it and read inf.
    edge = add_noise(np.full(n, range_max - sigma), sigma, range_min, range_max, rng)
    assert abs((edge == np.inf).mean() - 0.1587) < 0.005
    assert edge[np.isfinite(edge)].max() <= range_max
    # too near reads -inf (REP 117), never inf: SLAM takes inf as free space along the beam
    low = add_noise(np.full(n, range_min + sigma), sigma, range_min, range_max, rng)
    assert abs((low == -np.inf).mean() - 0.1587) < 0.005
    assert low[np.isfinite(low)].min() >= range_min
    assert np.all(add_noise(np.full(10, np.inf), sigma, range_min, range_max, rng) == np.inf)
    exact = add_noise(np.array([0.0, 0.05, 1.0, 7.0]), 0.0, range_min, range_max, rng)
    np.testing.assert_array_equal(exact, [-np.inf, -np.inf, 1.0, np.inf])


def as_set(segments: np.ndarray) -> set[tuple[float, ...]]:
    return {tuple(np.round(s, 9)) for s in segments}


def test_single_cell_gives_its_four_unit_edges():
    occ = np.zeros((4, 5), dtype=bool)
    occ[1, 3] = True
    got = occupancy_to_segments(occ, 1.0, (0.0, 0.0))
    assert got.shape == (4, 4)
    assert as_set(got) == {(3, 1, 4, 1), (3, 2, 4, 2), (3, 1, 3, 2), (4, 1, 4, 2)}


def test_l_shape_traces_six_maximal_edges_in_world_coordinates():
    occ = np.zeros((4, 4), dtype=bool)
    occ[0:3, 0] = True  # a vertical bar of 3 cells at column 0
    occ[0, 1:3] = True  # and a foot of 2 more cells along row 0
    res, origin = 0.5, (-1.0, 2.0)
    got = occupancy_to_segments(occ, res, origin)

    def w(x, y):
        return (origin[0] + x * res, origin[1] + y * res)

    expected = {
        (*w(0, 0), *w(3, 0)),  # bottom
        (*w(1, 1), *w(3, 1)),  # top of the foot
        (*w(0, 3), *w(1, 3)),  # top of the bar
        (*w(0, 0), *w(0, 3)),  # left
        (*w(1, 1), *w(1, 3)),  # right of the bar
        (*w(3, 0), *w(3, 1)),  # end of the foot
    }
    assert as_set(got) == {tuple(round(v, 9) for v in s) for s in expected}


def test_runs_do_not_merge_across_a_gap_and_cells_at_the_grid_edge_are_closed():
    occ = np.array([[True, True, False, True]])
    got = as_set(occupancy_to_segments(occ, 1.0, (0.0, 0.0)))
    assert got == {
        (0, 0, 2, 0),
        (0, 1, 2, 1),
        (3, 0, 4, 0),
        (3, 1, 4, 1),
        (0, 0, 0, 1),
        (2, 0, 2, 1),
        (3, 0, 3, 1),
        (4, 0, 4, 1),
    }


def ray_march(occ: np.ndarray, res: float, origin, start, angle: float) -> float:
    """Brute force, one cell at a time (Amanatides & Woo 1987): the distance at which the ray
    enters its first occupied cell."""
    rows, cols = occ.shape
    d = (math.cos(angle), math.sin(angle))
    pos = ((start[0] - origin[0]) / res, (start[1] - origin[1]) / res)
    cell = [math.floor(pos[0]), math.floor(pos[1])]
    step = [1 if v > 0 else -1 for v in d]
    next_t = [
        ((cell[i] + (step[i] > 0) - pos[i]) / d[i]) * res if d[i] != 0 else math.inf
        for i in range(2)
    ]
    delta = [abs(res / v) if v != 0 else math.inf for v in d]
    t = 0.0
    while 0 <= cell[0] < cols and 0 <= cell[1] < rows:
        if occ[cell[1], cell[0]]:
            return t
        axis = 0 if next_t[0] < next_t[1] else 1
        t = next_t[axis]
        cell[axis] += step[axis]
        next_t[axis] += delta[axis]
    return math.inf


def test_cast_against_grid_boundary_matches_a_cell_ray_march():
    rng = np.random.default_rng(3)
    occ = rng.random((30, 40)) < 0.08
    occ[[0, -1], :] = True
    occ[:, [0, -1]] = True
    res, origin = 0.1, (-1.3, 0.7)
    segments = occupancy_to_segments(occ, res, origin)
    free_r, free_c = np.nonzero(~occ)
    # Random points and headings: a ray exactly through the corner shared by two diagonal cells
    # touches both, which a cell march resolves either way; cell centres' 45° rays do that.
    for k in rng.choice(free_r.size, 5, replace=False):
        fx, fy = rng.uniform(0.1, 0.9, 2)
        start = (origin[0] + (free_c[k] + fx) * res, origin[1] + (free_r[k] + fy) * res)
        heading = rng.uniform(-math.pi, math.pi)
        cast = cast_scans([start], [heading], BEAMS, segments, NO_DISCS, 10.0)[0]
        marched = [ray_march(occ, res, origin, start, heading + b) for b in BEAMS]
        assert np.all(np.isfinite(cast))
        np.testing.assert_allclose(cast, marched, rtol=0, atol=1e-9)


MAP_YAML = (
    Path(__file__).resolve().parents[2].parent
    / "shared"
    / "data"
    / "maps"
    / "cob_ipa_apartment.yaml"
)


def test_ros_apartment_map_boundary_matches_a_cell_ray_march():
    if not MAP_YAML.exists():
        pytest.skip(f"shared map data not present: {MAP_YAML}")
    grid = load_ros_map(MAP_YAML)
    occupied, res, origin = grid.occupied, grid.resolution, grid.origin
    assert occupied.shape == (768, 544)
    segments = occupancy_to_segments(occupied, res, origin)
    assert len(segments) == 3626
    index = SegmentIndex(segments, reach=6.0)
    scene = map_scene(MAP_YAML, 3, RADIUS, seed=1)
    ranges = cast_scans(scene.origins, scene.headings, BEAMS, index, NO_DISCS, 6.0)
    assert np.isfinite(ranges).mean() > 0.5
    for origin_xy, heading, scan in zip(scene.origins, scene.headings, ranges, strict=True):
        marched = np.array(
            [ray_march(occupied, res, origin, origin_xy, heading + b) for b in BEAMS]
        )
        marched[marched > 6.0] = np.inf
        np.testing.assert_allclose(scan, marched, rtol=0, atol=1e-9)


def test_bench_lidar_command_prints_rays_per_second_as_json():
    result = CliRunner().invoke(
        app, ["bench", "lidar", "--seconds", "0.05", "--no-baseline", "--json"]
    )
    assert result.exit_code == 0, result.output
    rates = json.loads(result.stdout)["rays_per_s"]
    assert set(rates) == {"1x150", "100x150+discs", "1x5000", "1x5000 indexed"}
    assert all(r > 0 for r in rates.values())
