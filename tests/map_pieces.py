"""Robots' maps cut from one floor, each in its own frame, for the map merging tests and timing.

A floor is a function from world points to (occupied, observable). A robot's map is sampled at
its own cells' centres carried into the floor by the robot frame's transform, so a rotated map
is rasterized anew rather than resampled from another map (the code under test resamples).
:func:`lidar_map` instead builds it as the robot's SLAM does, from simulated scans along a
route: thin walls, shadows behind furniture, ray gaps far out.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
from slam_sim import scan

from agents.slam.occupancy import LogOddsGrid
from planners.grid import GridMap
from planners.map_merge import LogOddsMap, Transform2D

RES = 0.05
# the SLAM map's clamps (slam.p_max, slam.p_min in configs/fleet.yaml) as log-odds
L_OCC = math.log(0.97 / 0.03)
L_FREE = math.log(0.12 / 0.88)
LIMITS = (L_FREE, L_OCC)
DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "maps"

Floor = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


def box(x0: float, y0: float, x1: float, y1: float) -> list[tuple[float, float, float, float]]:
    return [(x0, y0, x1, y0), (x1, y0, x1, y1), (x1, y1, x0, y1), (x0, y1, x0, y0)]


def flat_segments() -> np.ndarray:
    """A 10 m × 7 m flat: four rooms with doorways, and furniture placed without symmetry."""
    walls = [
        *box(0.0, 0.0, 10.0, 7.0),
        (4.0, 0.0, 4.0, 2.5),
        (4.0, 3.5, 4.0, 7.0),
        (0.0, 4.5, 1.5, 4.5),
        (2.5, 4.5, 4.0, 4.5),
        (7.0, 0.0, 7.0, 3.0),
        (7.0, 4.0, 7.0, 7.0),
        (7.0, 3.0, 8.2, 3.0),
        (9.2, 3.0, 10.0, 3.0),
    ]
    furniture = (
        box(1.0, 1.0, 2.0, 1.6)
        + box(5.0, 5.5, 6.2, 6.4)
        + box(8.0, 0.5, 9.5, 1.0)
        + box(5.2, 1.2, 5.6, 1.6)
        + box(0.3, 5.8, 0.9, 6.7)
        + box(8.5, 5.0, 9.7, 5.4)
    )
    return np.array(walls + furniture)


def segment_floor(segments: np.ndarray, thickness: float = 0.1) -> Floor:
    """Walls ``thickness`` thick along ``segments``; observable inside their bounding box."""
    lo = segments.reshape(-1, 2).min(axis=0) - thickness / 2
    hi = segments.reshape(-1, 2).max(axis=0) + thickness / 2

    def floor(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a, b = segments[:, :2], segments[:, 2:]
        ab = b - a
        p = xy[..., None, :]
        t = np.clip(((p - a) * ab).sum(-1) / (ab * ab).sum(-1), 0.0, 1.0)
        d = np.linalg.norm(p - (a + t[..., None] * ab), axis=-1).min(axis=-1)
        inside = np.all((xy >= lo) & (xy <= hi), axis=-1)
        return d < thickness / 2, inside

    return floor


def grid_floor(grid: GridMap) -> Floor:
    """A raster floor (nearest cell); outside the grid and its unknown cells are unobservable."""

    def floor(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rc = grid.world_to_cell(xy)
        inside = grid.in_bounds(rc)
        r, c = np.where(inside, rc[..., 0], 0), np.where(inside, rc[..., 1], 0)
        return inside & grid.occupied[r, c], inside & ~grid.unknown[r, c]

    return floor


def piece(
    floor: Floor,
    seen: Callable[[np.ndarray], np.ndarray],
    to_floor: Transform2D,
    bounds: tuple[float, float, float, float],
    res: float = RES,
) -> LogOddsMap:
    """The map a robot whose frame ``to_floor`` carries into the floor's made of what it saw
    (``seen``: floor points → bool), on a grid of its own frame covering the floor ``bounds``
    (xmin, ymin, xmax, ymax)."""
    x0, y0, x1, y1 = bounds
    corners = to_floor.inverse().apply(np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]]))
    lo = np.floor(corners.min(axis=0) / res) * res
    cols, rows = np.ceil((corners.max(axis=0) - lo) / res).astype(int)
    cells = np.stack(np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij"), axis=-1)
    frame = GridMap(
        np.zeros((rows, cols), dtype=bool), np.zeros((rows, cols), dtype=bool), res, tuple(lo)
    )
    xy = to_floor.apply(frame.cell_to_world(cells))
    occupied, observable = floor(xy)
    known = observable & seen(xy)
    lo_odds = np.where(known, np.where(occupied, L_OCC, L_FREE), 0.0).astype(np.float32)
    return LogOddsMap(lo_odds, res, (float(lo[0]), float(lo[1])))


def truth_on(floor: Floor, like: LogOddsMap) -> GridMap:
    """The floor sampled at the cells of ``like``'s grid (its frame is the floor's)."""
    rows, cols = like.shape
    cells = np.stack(np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij"), axis=-1)
    empty = np.zeros((rows, cols), dtype=bool)
    xy = GridMap(empty, empty, like.resolution, like.origin).cell_to_world(cells)
    occupied, observable = floor(xy)
    return GridMap(occupied, ~observable, like.resolution, like.origin)


def free_iou(a: GridMap, b: GridMap) -> float:
    """Intersection over union of the free cells of two grids on the same cells."""
    return float((a.free & b.free).sum() / (a.free | b.free).sum())


def route(waypoints: list[tuple[float, float]], step: float = 0.25) -> np.ndarray:
    """Poses (x, y, heading) every ``step`` m along a polyline."""
    poses = []
    for (x0, y0), (x1, y1) in itertools.pairwise(waypoints):
        n = max(int(math.hypot(x1 - x0, y1 - y0) / step), 1)
        heading = math.atan2(y1 - y0, x1 - x0)
        poses += [(x0 + (x1 - x0) * k / n, y0 + (y1 - y0) * k / n, heading) for k in range(n)]
    return np.array(poses)


def lidar_map(
    segments: np.ndarray, poses: np.ndarray, to_floor: Transform2D, seed: int
) -> LogOddsMap:
    """The occupancy grid (``agents.slam.occupancy``, slam: section's hit/miss and clamps) of
    360-beam scans with 1 cm noise taken at the true ``poses`` (floor frame), in the frame that
    ``to_floor`` carries into the floor."""
    rng = np.random.default_rng(seed)
    into = to_floor.inverse()
    grid = LogOddsGrid((480, 480), (-12.0, -12.0), RES, 0.7, 0.4, 0.12, 0.97)
    for pose in poses:
        ranges, angle_min, inc = scan(segments, pose, rng=rng)
        hit = np.isfinite(ranges)
        angles = pose[2] + angle_min + inc * np.flatnonzero(hit)
        ends = pose[:2] + ranges[hit, None] * np.stack([np.cos(angles), np.sin(angles)], axis=-1)
        grid.insert(into.apply(pose[:2]), into.apply(ends))
    return LogOddsMap(grid.log_odds.copy(), RES, grid.origin)
