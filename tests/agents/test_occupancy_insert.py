"""One scan's ray update on a grid that holds only part of its rays: the same cells change as
on a grid holding them all, and the grid's touched box is the box of what changed."""

from __future__ import annotations

import numpy as np
import pytest

from agents.slam.occupancy import LogOddsGrid

RES = 0.05


def _grid(shape: tuple[int, int], origin: tuple[float, float]) -> LogOddsGrid:
    return LogOddsGrid(shape, origin, RES, 0.7, 0.4, 0.12, 0.97)


def _scan(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A sensor near the middle, ``n`` returns and a few missing rays' ends, up to 3 m away."""
    sensor = rng.uniform(-0.3, 0.3, 2)
    angle = rng.uniform(-np.pi, np.pi, n)
    reach = rng.uniform(0.2, 3.0, n)
    ends = sensor + reach[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    return sensor, ends[: n - n // 5], ends[n - n // 5 :]


def _changed_box(grid: LogOddsGrid) -> tuple[int, int, int, int]:
    rr, cc = np.nonzero(grid.log_odds)
    return int(rr.min()), int(rr.max()) + 1, int(cc.min()), int(cc.max()) + 1


@pytest.mark.parametrize("seed", range(6))
def test_rays_leaving_the_grid_change_the_cells_they_cross_inside_it(seed: int) -> None:
    rng = np.random.default_rng(seed)
    sensor, hits, misses = _scan(rng, 60)
    whole = _grid((160, 160), (-4.0, -4.0))  # every ray inside
    whole.insert(sensor, hits, misses)
    # a window of the same lattice cutting most rays: rows 60-99 and columns 50-109 of whole's
    part = _grid((40, 60), (-4.0 + 50 * RES, -4.0 + 60 * RES))
    part.insert(sensor, hits, misses)
    np.testing.assert_array_equal(part.log_odds, whole.log_odds[60:100, 50:110])
    assert whole.touched == _changed_box(whole)
    assert part.touched == _changed_box(part)


def test_a_scan_wholly_inside_touches_the_box_of_its_cells_only() -> None:
    rng = np.random.default_rng(7)
    sensor, hits, misses = _scan(rng, 40)
    grid = _grid((160, 160), (-4.0, -4.0))
    grid.insert(sensor, hits, misses)
    assert grid.touched == _changed_box(grid)
    before = grid.touched
    grid.insert(sensor, hits[:3], None)  # a narrower scan adds nothing to the box
    assert grid.touched == before
