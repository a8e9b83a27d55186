"""Paths repaired around the bodies of lost robots (planners.bodies)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from planners.bodies import reroute, with_bodies
from planners.grid import GridMap, clearance
from planners.polyline import densify

RES = 0.025
RADIUS = 0.185  # a robot centre keeps this from every blocked cell
BODY = 0.17


def _room(width: float, height: float, walls: list[tuple[float, float, float, float]] = ()):
    """A walled rectangle of free floor, with extra wall boxes (x0, y0, x1, y1)."""
    rows, cols = round(height / RES) + 2, round(width / RES) + 2
    occupied = np.zeros((rows, cols), dtype=bool)
    occupied[[0, -1], :] = occupied[:, [0, -1]] = True
    grid = GridMap(occupied, np.zeros_like(occupied), RES, (-RES, -RES))
    xy = grid.cell_to_world(np.stack(np.mgrid[0:rows, 0:cols], axis=-1))
    for x0, y0, x1, y1 in walls:
        occupied |= (
            (xy[..., 0] >= x0) & (xy[..., 0] <= x1) & (xy[..., 1] >= y0) & (xy[..., 1] <= y1)
        )
    return GridMap(occupied, np.zeros_like(occupied), RES, (-RES, -RES))


def _free(grid: GridMap, bodies: list[tuple[float, float]]) -> tuple[GridMap, np.ndarray]:
    blocked = with_bodies(grid, np.array(bodies), BODY)
    return blocked, clearance(blocked) >= RADIUS


def _on_free(path: np.ndarray, grid: GridMap, free: np.ndarray) -> bool:
    """Every point of ``path`` in a free cell, or at most a cell from one (the path is looked
    up at a third of a cell, so it may graze a blocked cell's corner between two samples)."""
    rc = grid.world_to_cell(densify(path, RES / 10))
    if not grid.in_bounds(rc).all():
        return False
    to_free = ndimage.distance_transform_edt(~free) * RES
    return bool((to_free[rc[:, 0], rc[:, 1]] <= RES).all())


def test_a_lane_through_a_body_goes_round_it() -> None:
    grid, free = _free(_room(4.0, 3.0), [(2.0, 1.5)])
    lane = np.array([[0.5, 1.5], [3.5, 1.5]])
    out = reroute(lane, free, grid, min_run=RES)
    assert out.changed and len(out.paths) == 1
    path = out.paths[0]
    assert np.allclose(path[0], lane[0]) and np.allclose(path[-1], lane[-1])
    assert _on_free(path, grid, free)
    # the detour keeps the robot's centre two radii and more from the body's centre
    gaps = np.hypot(*(densify(path, RES / 4) - [2.0, 1.5]).T)
    assert gaps.min() >= BODY + RADIUS - RES
    assert len(out.dropped) == 1
    dropped = out.dropped[0]
    assert dropped[0, 0] < 2.0 < dropped[-1, 0]
    assert np.allclose(dropped[:, 1], 1.5)


def test_a_body_in_the_only_way_splits_the_path() -> None:
    # two rooms joined by a corridor 0.5 m wide; the body stands in the corridor
    walls = [(1.9, 0.0, 2.6, 1.25), (1.9, 1.75, 2.6, 3.0)]
    grid, free = _free(_room(4.5, 3.0, walls), [(2.25, 1.5)])
    path = np.array([[0.5, 0.5], [0.5, 1.5], [4.0, 1.5], [4.0, 0.5]])
    out = reroute(path, free, grid, min_run=RES)
    assert len(out.paths) == 2, "no way round the body: the path falls apart"
    first, second = out.paths
    assert np.allclose(first[0], path[0]) and np.allclose(second[-1], path[-1])
    assert first[:, 0].max() < 2.0 < second[:, 0].min()
    for part in out.paths:
        assert _on_free(part, grid, free)


def test_without_bodies_the_path_stays() -> None:
    grid, free = _free(_room(4.0, 3.0), [])
    path = np.array([[0.5, 0.5], [3.5, 0.5], [3.5, 1.0], [0.5, 1.0]])
    out = reroute(path, free, grid, min_run=RES)
    assert not out.changed
    assert len(out.paths) == 1 and np.array_equal(out.paths[0], path)


def test_a_path_entirely_under_a_body_leaves_nothing() -> None:
    grid, free = _free(_room(4.0, 3.0), [(2.0, 1.5)])
    out = reroute(np.array([[1.9, 1.5], [2.1, 1.5]]), free, grid, min_run=RES)
    assert out.paths == () and len(out.dropped) == 1


@pytest.mark.parametrize("seed", range(20))
def test_every_repaired_path_runs_on_free_cells(seed: int) -> None:
    rng = np.random.default_rng(seed)
    bodies = [tuple(rng.uniform([0.6, 0.6], [3.4, 2.4])) for _ in range(rng.integers(1, 4))]
    grid, free = _free(_room(4.0, 3.0), bodies)
    ys = np.arange(0.3, 2.75, 0.25)
    lanes = [[[0.3, y], [3.7, y]][:: 1 if k % 2 == 0 else -1] for k, y in enumerate(ys)]
    path = np.array([p for lane in lanes for p in lane])
    out = reroute(path, free, grid, min_run=RES)
    assert out.changed
    for part in out.paths:
        assert len(part) >= 2 and _on_free(part, grid, free)
    swept = sum(float(np.hypot(*np.diff(p, axis=0).T).sum()) for p in out.paths)
    assert swept > 0.5 * float(np.hypot(*np.diff(path, axis=0).T).sum())


def test_a_detour_longer_than_allowed_splits_the_path() -> None:
    # a table right below the lane and a wall right above: round the body only via the far
    # side of the table, metres farther than the gap
    grid, free = _free(_room(4.0, 3.0, [(1.0, 0.6, 3.0, 2.05)]), [(2.0, 2.55)])
    lane = np.array([[0.4, 2.55], [3.6, 2.55]])
    long_way = reroute(lane, free, grid, min_run=RES)
    assert len(long_way.paths) == 1  # joined: down round the table and back up
    assert float(np.hypot(*np.diff(long_way.paths[0], axis=0).T).sum()) > 3.2 + 2.0
    split = reroute(lane, free, grid, min_run=RES, max_detour=1.0)
    assert len(split.paths) == 2
    assert split.paths[0][:, 0].max() < 2.0 < split.paths[1][:, 0].min()
