"""One pass over a patch of floor no tour planned (furniture taken away): lanes along the
patch's longer side, then fill-in passes for what they miss, from robot centres only."""

import numpy as np
import pytest
from coverage_maps import boxed, grid_of

from planners.coverage.metrics import swath
from planners.coverage.patch import patch_lanes, patch_sweep
from planners.coverage.transit import Transit
from planners.grid import GridMap, clearance, dilate, reachable
from planners.polyline import densify

RES = 0.025
HALF = 0.15
SPACING = 0.25


def room(occ: np.ndarray) -> tuple[GridMap, np.ndarray]:
    """The grid of ``occ`` and its robot-centre cells (radius 0.17)."""
    g = grid_of(occ, res=RES)
    return g, reachable(clearance(g) >= 0.17, g.world_to_cell(np.array([[0.5, 0.5]])))


def patch(g: GridMap, x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    """The cells of ``g`` whose centres lie in the box."""
    xy = g.cell_to_world(np.stack(np.mgrid[0 : g.shape[0], 0 : g.shape[1]], axis=-1))
    return (xy[..., 0] > x0) & (xy[..., 0] < x1) & (xy[..., 1] > y0) & (xy[..., 1] < y1)


def _check_sweep(
    g: GridMap, floor: np.ndarray, reach: np.ndarray, target: float = 1.0
) -> tuple[np.ndarray, float]:
    """The patch's sweep: robot centres on centre cells only, its area what its swath sweeps
    of the patch, and all of the patch swept (``target`` 1)."""
    sweep = patch_sweep(g, floor, reach, HALF, SPACING, Transit(g, reach), target)
    assert sweep is not None
    path, area = sweep
    rc = g.world_to_cell(path)
    assert reach[rc[:, 0], rc[:, 1]].all(), "a waypoint off the centre cells"
    # between waypoints too the robot keeps its radius from walls (a diagonal step between
    # centre cells passes the corner they share)
    rc = g.world_to_cell(densify(path, g.resolution / 4))
    assert clearance(g)[rc[:, 0], rc[:, 1]].min() >= 0.17 - g.resolution
    assert len(path) >= 2 and (np.diff(path, axis=0) != 0).any(), "nothing to drive"
    swept = swath(g, path, HALF)[0] & floor
    assert area == pytest.approx(swept.sum() * g.resolution**2)
    if target == 1.0:
        assert not (floor & ~swept).any(), "floor of the patch left unswept"
    return path, area


def test_a_patch_is_swept_by_lanes_along_its_longer_side() -> None:
    g, reach = room(boxed(120, 160))  # 3 m × 4 m at 2.5 cm
    floor = patch(g, 1.5, 1.0, 2.7, 1.6) & reach
    lanes = patch_lanes(g, floor, reach, HALF, SPACING)
    # 0.6 m wide: three lines of at most 0.25 m apart, each one run along x
    assert len(lanes) == 3
    assert all(abs(a[1] - b[1]) < 1e-9 and abs(a[0] - b[0]) > 1.0 for a, b in lanes)
    ys = sorted(a[1] for a, _ in lanes)
    assert np.diff(ys).max() <= SPACING + 1e-9
    # boustrophedon: each line driven the other way from the one before
    assert lanes[0][1][0] > lanes[0][0][0] and lanes[1][1][0] < lanes[1][0][0]
    # no lane runs on past the patch's ends: the brush reaches them from within
    xs = np.concatenate([lane[:, 0] for lane in lanes])
    assert xs.min() > 1.5 and xs.max() < 2.7
    path, _ = _check_sweep(g, floor, reach)
    # the lanes and the transits between them, nothing more
    assert len(path) == 6


def test_a_tall_patch_gets_lanes_along_y() -> None:
    g, reach = room(boxed(160, 120))
    floor = patch(g, 1.0, 1.5, 1.6, 2.7) & reach
    lanes = patch_lanes(g, floor, reach, HALF, SPACING)
    assert len(lanes) == 3 and all(abs(a[0] - b[0]) < 1e-9 for a, b in lanes)
    _check_sweep(g, floor, reach)


def test_floor_by_a_wall_that_no_lane_line_reaches_is_left_to_fill_in_passes() -> None:
    occ = boxed(120, 160)
    occ[60:, 80] = True  # a partition wall up from the room's middle
    g, reach = room(occ)
    # floor on both sides of the partition and along the outer wall: centres cannot take
    # every line, the lanes are cut at the partition
    floor = patch(g, 1.2, 1.3, 2.8, 2.95) & g.free
    floor &= dilate(reach, HALF, g.resolution)  # what the brush reaches
    path, _ = _check_sweep(g, floor, reach)
    # the lanes end at the partition, and the pass goes round it for the rest
    assert (path[:, 0] < 2.0).any() and (path[:, 0] > 2.0).any()


def test_a_patch_of_a_few_cells_is_still_a_path_to_drive() -> None:
    g, reach = room(boxed(120, 160))
    floor = patch(g, 2.0, 1.5, 2.06, 1.56)
    path, area = _check_sweep(g, floor, reach)
    assert len(path) == 2
    assert area == pytest.approx(floor.sum() * g.resolution**2)


def test_no_floor_no_sweep() -> None:
    g, reach = room(boxed(40, 40))
    empty = np.zeros(g.shape, dtype=bool)
    assert patch_lanes(g, empty, reach, HALF, SPACING) == []
    assert patch_sweep(g, empty, reach, HALF, SPACING, Transit(g, reach)) is None


def test_the_fill_in_stops_at_the_target() -> None:
    occ = boxed(120, 160)
    occ[60:, 80] = True
    g, reach = room(occ)
    floor = patch(g, 1.2, 1.3, 2.8, 2.95) & g.free & dilate(reach, HALF, g.resolution)
    every, _ = _check_sweep(g, floor, reach)
    enough, area = _check_sweep(g, floor, reach, 0.995)
    assert len(enough) < len(every)
    assert area >= 0.995 * floor.sum() * g.resolution**2 - 1e-9


def test_strips_no_lane_line_reaches_are_swept_one_after_the_other_nearest_end_first() -> None:
    g, reach = room(boxed(120, 160))
    brushed = dilate(reach, HALF, g.resolution)
    # two strips along the south wall, too close to it for a robot centre: fill-in only
    strips = (patch(g, 1.0, 0.04, 1.6, 0.09) | patch(g, 2.0, 0.04, 2.6, 0.09)) & brushed
    assert patch_lanes(g, strips, reach, HALF, SPACING) == []
    path, _ = _check_sweep(g, strips, reach)
    # one step from the end of one strip into the other, at its nearer end
    steps = np.hypot(*np.diff(path, axis=0).T)
    assert (steps > 0.3).sum() == 1
    k = int(np.argmax(steps))
    assert steps[k] < np.hypot(*(path[-1] - path[k]))


def test_a_corner_the_brush_just_reaches_is_a_path_of_two_points() -> None:
    g, reach = room(boxed(120, 160))
    # one cell towards the room's corner that only the corner-most centre cell's brush reaches
    centre = np.argwhere(reach)[np.argmin(np.argwhere(reach).sum(axis=1))]
    corner = np.zeros(g.shape, dtype=bool)
    corner[centre[0] - 4, centre[1] - 4] = True
    assert patch_lanes(g, corner, reach, HALF, SPACING) == []
    path, _ = _check_sweep(g, corner, reach)
    assert len(path) == 2 and np.allclose(path[0], g.cell_to_world(centre))
