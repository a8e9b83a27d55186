"""The side brush in the simulator's cleaning truth: what it sweeps, what coverage and
repetition make of it, and the config that describes it."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from fleet.config import ConfigError
from fleet.params import load_fleet_config
from fleet.protocol import CoverageImage
from fleet.report.summary import side_brush_only
from planners.grid import GridMap
from planners.robot import SideBrush
from sim_server.cleaning import CleaningGrid

RES = 0.01
WIDTH = 0.30
BRUSH = SideBrush(enabled=True, reach=0.22, radius=0.07, angle=-1.0)


def _grid(rows: int = 100, cols: int = 300) -> GridMap:
    blocked = np.zeros((rows, cols), dtype=bool)
    return GridMap(blocked, blocked.copy(), RES, (0.0, 0.0))


def _drive(cleaning: CleaningGrid, path: np.ndarray, robot: str = "r") -> None:
    for pose in path:
        cleaning.update([robot], pose[None])


def _straight(x0: float, x1: float, y: float, theta: float, step: float = 0.02) -> np.ndarray:
    xs = np.arange(x0, x1 + 1e-9, step)
    return np.column_stack([xs, np.full_like(xs, y), np.full_like(xs, theta)])


def _lateral_extent(mask: np.ndarray, grid: GridMap, column: int) -> tuple[float, float]:
    rows = np.nonzero(mask[:, column])[0]
    ys = grid.origin[1] + (rows + 0.5) * grid.resolution
    return float(ys.min()), float(ys.max())


def test_a_straight_drive_sweeps_the_brush_side_beyond_the_main_brush() -> None:
    """Driving along +x with the brush on the right, the swept band reaches the bristles' tip
    on the right (lateral reach (reach − radius)·|sin angle| + radius) and only the main brush
    on the left."""
    grid = _grid()
    cleaning = CleaningGrid(grid, np.ones(grid.shape, dtype=bool), WIDTH, BRUSH)
    _drive(cleaning, _straight(0.5, 2.5, 0.5, 0.0))
    lo, hi = _lateral_extent(cleaning.swept_mask(), grid, 150)
    lateral = (BRUSH.reach - BRUSH.radius) * abs(math.sin(BRUSH.angle)) + BRUSH.radius
    assert lo == pytest.approx(0.5 - lateral, abs=RES)
    assert hi == pytest.approx(0.5 + WIDTH / 2, abs=RES)
    main_lo, _ = _lateral_extent(cleaning.visits > 0, grid, 150)
    assert main_lo == pytest.approx(0.5 - WIDTH / 2, abs=RES)


def test_the_brush_on_the_left_sweeps_the_left() -> None:
    grid = _grid()
    left = SideBrush(enabled=True, reach=0.22, radius=0.07, angle=1.0)
    cleaning = CleaningGrid(grid, np.ones(grid.shape, dtype=bool), WIDTH, left)
    _drive(cleaning, _straight(0.5, 2.5, 0.5, 0.0))
    lo, hi = _lateral_extent(cleaning.swept_mask(), grid, 150)
    assert lo == pytest.approx(0.5 - WIDTH / 2, abs=RES)
    assert hi > 0.5 + WIDTH / 2 + 0.03


def test_coverage_counts_the_side_brush_and_repetition_does_not() -> None:
    """The same two passes with and without the brush: coverage grows by the side band, the
    main brush's visits and repetition are the same."""
    grid = _grid()
    path = np.vstack([_straight(0.3, 2.7, 0.35, 0.0), _straight(0.3, 2.7, 0.6, 0.0)])
    plain = CleaningGrid(grid, np.ones(grid.shape, dtype=bool), WIDTH)
    brushed = CleaningGrid(grid, np.ones(grid.shape, dtype=bool), WIDTH, BRUSH)
    _drive(plain, path[:, :2])
    _drive(brushed, path)
    assert np.array_equal(plain.visits, brushed.visits)
    assert brushed.repetition() == pytest.approx(plain.repetition())
    assert plain.repetition() > 0.1
    swept = brushed.swept_mask()
    assert brushed.coverage() == pytest.approx(swept.sum() / swept.size)
    assert brushed.coverage() > plain.coverage() + 0.03
    assert brushed.side.any() and not plain.side.any()


def test_turning_in_place_sweeps_a_ring() -> None:
    """A robot that only turns moves its side brush round a circle: the ring between the main
    brush and the bristles' tip is swept, nothing beyond it."""
    grid = _grid(100, 100)
    cleaning = CleaningGrid(grid, np.ones(grid.shape, dtype=bool), WIDTH, BRUSH)
    thetas = np.linspace(0.0, 2 * math.pi, 64)
    _drive(cleaning, np.column_stack([np.full(64, 0.5), np.full(64, 0.5), thetas]))
    centres = grid.cell_to_world(np.argwhere(np.ones(grid.shape, dtype=bool)))
    dist = np.hypot(centres[:, 0] - 0.5, centres[:, 1] - 0.5).reshape(grid.shape)
    swept = cleaning.swept_mask()
    assert swept[(dist > WIDTH / 2 + 0.01) & (dist < BRUSH.reach - 0.01)].all()
    assert not swept[dist > BRUSH.reach + 0.01].any()
    assert cleaning.visits.max() == 1


def test_a_turn_alone_counts_as_a_move() -> None:
    """A quarter turn moves the bristles by far more than a quarter cell: it sweeps, although
    the centre stayed put."""
    grid = _grid(100, 100)
    cleaning = CleaningGrid(grid, np.ones(grid.shape, dtype=bool), WIDTH, BRUSH)
    cleaning.update(["r"], np.array([[0.5, 0.5, 0.0]]))
    before = cleaning.side.sum()
    cleaning.update(["r"], np.array([[0.5, 0.5, 0.5]]))
    assert cleaning.side.sum() > before


def test_a_side_brush_needs_headings() -> None:
    grid = _grid()
    cleaning = CleaningGrid(grid, np.ones(grid.shape, dtype=bool), WIDTH, BRUSH)
    with pytest.raises(ValueError, match="headings"):
        cleaning.update(["r"], np.array([[0.5, 0.5]]))


def test_a_brush_that_is_off_sweeps_nothing() -> None:
    grid = _grid()
    off = SideBrush(enabled=False)
    cleaning = CleaningGrid(grid, np.ones(grid.shape, dtype=bool), WIDTH, off)
    _drive(cleaning, _straight(0.5, 2.5, 0.5, 0.0))
    assert not cleaning.side.any()


def _config_with(tmp_path: Path, **brush: object) -> Path:
    data = yaml.safe_dump({"robot": _robot() | {"side_brush": brush}})
    path = tmp_path / "fleet.yaml"
    path.write_text(data)
    return path


def _robot() -> dict[str, object]:
    robot = load_fleet_config().robot
    return {
        k: getattr(robot, k)
        for k in (
            "radius",
            "wheel_base",
            "cleaning_width",
            "max_vel_x",
            "max_vel_theta",
            "acc_lim_x",
            "acc_lim_theta",
            "mass",
        )
    }


@pytest.mark.parametrize(
    ("brush", "field"),
    [
        ({"enabled": True, "reach": 0.5}, "side_brush.reach (0.5) must not exceed radius + 0.1"),
        ({"enabled": True, "reach": 0.12, "radius": 0.05}, "must exceed half cleaning_width"),
        ({"reach": 0.2, "radius": 0.3}, "radius (0.3) must not exceed reach (0.2)"),
        ({"radius": 0.0}, "radius must be > 0"),
        ({"angle": 4.0}, "angle (4.0) must lie in [-pi, pi]"),
    ],
)
def test_a_side_brush_out_of_bounds_is_refused_by_name(
    tmp_path: Path, brush: dict[str, object], field: str
) -> None:
    path = _config_with(tmp_path, **brush)
    with pytest.raises(ConfigError) as err:
        load_fleet_config(path)
    assert str(err.value).startswith(f"{path}: robot"), err.value
    assert field in str(err.value)


def test_the_default_config_has_the_side_brush_off() -> None:
    brush = load_fleet_config().robot.side_brush
    assert not brush.enabled
    assert brush.reach > load_fleet_config().robot.radius


def test_the_report_counts_the_floor_only_the_side_brush_swept() -> None:
    """Of 6 cleanable cells, the main brush swept 2, the side brush 3 of which 1 the main brush
    also swept: 2 of 6 were the side brush's alone; without a side mask, none."""
    visits = np.array([1, 2, 0, 0, 0, 0], dtype=np.uint16)
    cleanable = np.ones(6, dtype=np.uint8)
    side = np.array([0, 1, 1, 1, 0, 0], dtype=np.uint8)
    image = CoverageImage(0.0, 0.05, 0.0, 0.0, 2, 3, visits, cleanable, side)
    assert side_brush_only(image) == pytest.approx(2 / 6, abs=1e-5)
    assert image.swept().sum() == 4
    plain = CoverageImage(0.0, 0.05, 0.0, 0.0, 2, 3, visits, cleanable)
    assert side_brush_only(plain) == 0.0 and plain.swept().sum() == 2
