"""Ground-truth cleaning: swept segments against dense sampling of the brush along the path."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from planners.grid import GridMap, disc
from sim_server.cleaning import CleaningGrid

RES = 0.05
WIDTH = 0.30
R = WIDTH / 2


def _grid(rows: int = 44, cols: int = 44) -> GridMap:
    blocked = np.zeros((rows, cols), dtype=bool)
    return GridMap(blocked, blocked.copy(), RES, (-0.1, -0.1))


def _cleaning(grid: GridMap) -> CleaningGrid:
    return CleaningGrid(grid, np.ones(grid.shape, dtype=bool), WIDTH)


def _dense_visits(grid: GridMap, path: np.ndarray, spacing: float = 1e-3) -> np.ndarray:
    """Visit counts from the brush sampled every ``spacing`` m along the polyline ``path``:
    a cell counts each time it is under the brush at a sample and was not at the one before."""
    points = [path[:1]]
    for a, b in itertools.pairwise(path):
        n = max(1, int(np.ceil(np.hypot(*(b - a)) / spacing)))
        points.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    samples = np.vstack(points)
    rows, cols = grid.shape
    centres = grid.cell_to_world(np.argwhere(np.ones((rows, cols), dtype=bool)))
    visits = np.zeros(rows * cols, dtype=np.int64)
    before = np.zeros(rows * cols, dtype=bool)
    for chunk in np.array_split(samples, max(1, len(samples) // 1000)):
        d2 = (chunk[:, None, 0] - centres[None, :, 0]) ** 2
        d2 += (chunk[:, None, 1] - centres[None, :, 1]) ** 2
        inside = d2 < (R - 1e-9) ** 2
        visits += (inside & ~np.vstack([before, inside[:-1]])).sum(axis=0)
        before = inside[-1]
    return visits.reshape(rows, cols)


def _distance_to_path(points: np.ndarray, path: np.ndarray) -> np.ndarray:
    a, b = path[:-1], path[1:]
    seg = b - a
    rel = points[:, None, :] - a[None]
    along = np.clip(np.einsum("psk,sk->ps", rel, seg) / np.einsum("sk,sk->s", seg, seg), 0, 1)
    return np.hypot(*np.moveaxis(rel - along[..., None] * seg[None], -1, 0)).min(axis=1)


def _random_path(seed: int, steps: int = 120) -> np.ndarray:
    """A wandering path in a 2 m square that crosses itself, with steps of 1.5 to 12 cm."""
    rng = np.random.default_rng(seed)
    heading = rng.uniform(0, 2 * np.pi)
    path = [np.array([1.0, 1.0])]
    while len(path) <= steps:
        heading += rng.normal(0.0, 0.6)
        p = path[-1] + rng.uniform(0.015, 0.12) * np.array([np.cos(heading), np.sin(heading)])
        if np.all((p > 0.3) & (p < 1.7)):
            path.append(p)
        else:
            heading += np.pi
    return np.array(path)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_swept_segments_equal_dense_sampling_along_the_path(seed: int) -> None:
    grid = _grid()
    path = _random_path(seed)
    cleaning = _cleaning(grid)
    for xy in path:
        cleaning.update(["r"], xy[None])
    dense = _dense_visits(grid, path)
    assert dense.max() >= 3, "the path should cross itself, so cells are entered repeatedly"
    differ = np.argwhere(cleaning.visits != dense)
    # Only a cell whose centre is on the brush's rim (within float noise) may differ: dense
    # sampling can step over the instant it is under the brush.
    rim = np.abs(_distance_to_path(grid.cell_to_world(differ), path) - R) < 1e-6
    assert rim.all(), differ[~rim]
    assert len(differ) <= 2


def test_a_straight_drive_cleans_the_capsule_around_it() -> None:
    grid = _grid()
    start, end = np.array([0.33, 0.52]), np.array([1.71, 0.97])
    cleaning = _cleaning(grid)
    cleaning.update(["r"], start[None])
    cleaning.update(["r"], end[None])
    centres = grid.cell_to_world(np.argwhere(np.ones(grid.shape, dtype=bool)))
    capsule = _distance_to_path(centres, np.array([start, end])) < R - 1e-9
    np.testing.assert_array_equal(cleaning.visits.reshape(-1), capsule.astype(np.uint16))


def test_first_update_cleans_the_footprint_of_planners_grid_disc() -> None:
    grid = _grid()
    cleaning = _cleaning(grid)
    cell = np.array([20, 17])
    cleaning.update(["r"], grid.cell_to_world(cell)[None])
    kernel = disc(R, RES)
    k = kernel.shape[0] // 2
    expected = np.zeros(grid.shape, dtype=np.uint16)
    expected[cell[0] - k : cell[0] + k + 1, cell[1] - k : cell[1] + k + 1] = kernel
    np.testing.assert_array_equal(cleaning.visits, expected)


def test_jitter_below_a_quarter_cell_adds_nothing() -> None:
    grid = _grid()
    cleaning = _cleaning(grid)
    cleaning.update(["r"], np.array([[1.013, 1.0]]))
    before = cleaning.visits.copy()
    rng = np.random.default_rng(0)
    for _ in range(200):
        cleaning.update(["r"], np.array([[1.013, 1.0]]) + rng.uniform(-0.006, 0.006, (1, 2)))
    np.testing.assert_array_equal(cleaning.visits, before)
    cleaning.update(["r"], np.array([[1.013 + RES, 1.0]]))
    assert cleaning.visits.sum() > before.sum()
    assert cleaning.visits.max() == 1


def test_robots_in_one_update_count_as_if_updated_one_by_one() -> None:
    grid = _grid()
    together, alone = _cleaning(grid), _cleaning(grid)
    a = np.array([[0.5, 0.5], [0.8, 0.6], [1.2, 0.9], [1.25, 1.4]])
    b = np.array([[0.7, 0.5], [0.9, 0.55], [1.2, 1.0], [1.5, 1.5]])
    for pa, pb in zip(a, b, strict=True):
        together.update(["a", "b"], np.stack([pa, pb]))
        alone.update(["a"], pa[None])
        alone.update(["b"], pb[None])
    np.testing.assert_array_equal(together.visits, alone.visits)
    assert together.visits.max() == 2, "cells under both brushes count once per robot"


def test_a_robot_that_left_starts_a_fresh_pass() -> None:
    grid = _grid()
    cleaning = _cleaning(grid)
    cleaning.update(["r"], np.array([[1.0, 1.0]]))
    once = cleaning.visits.copy()
    cleaning.update(["r"], np.array([[1.0, 1.0]]))
    np.testing.assert_array_equal(cleaning.visits, once)
    cleaning.forget("r")
    cleaning.update(["r"], np.array([[1.0, 1.0]]))
    np.testing.assert_array_equal(cleaning.visits, 2 * once)


def test_cells_outside_the_grid_are_ignored() -> None:
    grid = _grid(10, 10)
    cleaning = _cleaning(grid)
    cleaning.update(["r"], np.array([[-0.1, -0.1]]))
    cleaning.update(["r"], np.array([[0.6, -0.1]]))
    assert cleaning.visits.sum() > 0
    assert cleaning.visits[5:].sum() == 0


def test_coverage_and_repetition_kept_as_cells_are_swept_equal_a_recount() -> None:
    grid = _grid()
    # Half the floor cleanable, two robots whose paths cross each other and themselves, so
    # one update sweeps some cells twice and some outside the cleanable half.
    cleanable = np.zeros(grid.shape, dtype=bool)
    cleanable[:, : grid.shape[1] // 2] = True
    cleaning = CleaningGrid(grid, cleanable, WIDTH)
    paths = [_random_path(3), _random_path(4)]
    for step, xy in enumerate(zip(*paths, strict=True)):
        cleaning.update(["a", "b"], np.array(xy))
        if step % 10 == 0 or step == len(paths[0]) - 1:
            v = cleaning.visits[cleanable]
            swept = np.count_nonzero(v)
            assert cleaning.coverage() == swept / cleanable.sum()
            assert cleaning.repetition() == (v.sum() / swept - 1.0 if swept else 0.0)
    assert cleaning.repetition() > 0.5
    assert cleaning.cleanable_m2 == pytest.approx(cleanable.sum() * RES**2)
