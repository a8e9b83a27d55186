"""Scenes and timing for the lidar benchmark (``fleet bench lidar``).

A scene is a furnished rectangular floor: the outer walls plus randomly placed, rotated boxes
(four edges each) at the density of the built-in home world (about one box per 1.3 m²), and
robots at random free positions. Timings report rays per second of :func:`cast_scans` and of the
brute-force :func:`cast_scans_reference` on the same scene.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sim_server.lidar import SegmentIndex, cast_scans, cast_scans_reference, occupancy_to_segments

_FLOOR_PER_BOX = 1.3


@dataclass(frozen=True)
class Scene:
    segments: np.ndarray
    origins: np.ndarray
    headings: np.ndarray
    discs: np.ndarray
    self_index: np.ndarray


def furnished_scene(n_segments: int, n_robots: int, robot_radius: float, seed: int = 0) -> Scene:
    """A square floor with 4 walls and (n_segments − 4) / 4 boxes, and n_robots robot discs of
    ``robot_radius``."""
    rng = np.random.default_rng(seed)
    n_boxes = max(0, math.ceil((n_segments - 4) / 4))
    side = max(4.0, math.sqrt(n_boxes * _FLOOR_PER_BOX))
    walls = np.array(
        [[0, 0, side, 0], [side, 0, side, side], [side, side, 0, side], [0, side, 0, 0]]
    )
    centre = rng.uniform(0.5, side - 0.5, size=(n_boxes, 2))
    half = rng.uniform(0.15, 0.6, size=(n_boxes, 2))
    angle = rng.uniform(0, math.pi, size=n_boxes)
    corner_signs = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]])
    local = corner_signs[None] * half[:, None]
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    corners = centre[:, None] + np.stack(
        [c * local[..., 0] - s * local[..., 1], s * local[..., 0] + c * local[..., 1]], axis=-1
    )
    edges = np.concatenate([corners, np.roll(corners, -1, axis=1)], axis=-1).reshape(-1, 4)
    segments = np.concatenate([walls, edges])[: max(n_segments, 4)]
    clearance = np.hypot(half[:, 0], half[:, 1]) + robot_radius
    origins = []
    while len(origins) < n_robots:
        p = rng.uniform(robot_radius, side - robot_radius, size=2)
        if np.all(np.hypot(*(centre - p).T) > clearance):
            origins.append(p)
    origins = np.array(origins).reshape(-1, 2)
    discs = np.column_stack([origins, np.full(n_robots, robot_radius)])
    return Scene(
        segments=segments.astype(np.float64),
        origins=origins,
        headings=rng.uniform(-math.pi, math.pi, size=n_robots),
        discs=discs,
        self_index=np.arange(n_robots),
    )


def map_scene(yaml_path: Path, n_robots: int, robot_radius: float, seed: int = 0) -> Scene:
    """The boundary segments of a ROS map, with robot discs of ``robot_radius`` at random free
    cells clear of walls."""
    from scipy.ndimage import binary_erosion

    from fleet.world import load_ros_map

    grid = load_ros_map(yaml_path)
    free, res, origin = grid.free, grid.resolution, grid.origin
    segments = occupancy_to_segments(grid.occupied, res, origin)
    rng = np.random.default_rng(seed)
    margin = int(np.ceil(2 * robot_radius / res))
    clear = binary_erosion(free, iterations=margin)
    free_r, free_c = np.nonzero(clear)
    pick = rng.choice(free_r.size, size=n_robots, replace=False)
    origins = np.column_stack(
        [origin[0] + (free_c[pick] + 0.5) * res, origin[1] + (free_r[pick] + 0.5) * res]
    )
    return Scene(
        segments=segments,
        origins=origins,
        headings=rng.uniform(-math.pi, math.pi, size=n_robots),
        discs=np.column_stack([origins, np.full(n_robots, robot_radius)]),
        self_index=np.arange(n_robots),
    )


def rays_per_second(
    scene: Scene,
    beams: int,
    range_max: float,
    *,
    reference: bool = False,
    indexed: bool = False,
    min_seconds: float = 0.5,
) -> float:
    """Rays per second of one full scan of every robot in the scene, timed over ≥ min_seconds."""
    angles = np.linspace(0.0, 2 * math.pi, beams, endpoint=False)
    segments = SegmentIndex(scene.segments, reach=range_max) if indexed else scene.segments
    cast = cast_scans_reference if reference else cast_scans
    args = (scene.origins, scene.headings, angles, segments, scene.discs, range_max)
    cast(*args, scene.self_index)
    calls, start = 0, time.perf_counter()
    while (elapsed := time.perf_counter() - start) < min_seconds:
        cast(*args, scene.self_index)
        calls += 1
    return calls * scene.origins.shape[0] * beams / elapsed


def run_bench(
    robot_radius: float,
    beams: int,
    range_max: float,
    min_seconds: float,
    map_yaml: Path | None = None,
    baseline: bool = True,
) -> list[dict[str, Any]]:
    """The bench's rows: rays per second on the fixed configurations (1 robot with 150
    segments, 100 robots seeing each other's discs with 150, 1 robot with 5000 with and
    without a SegmentIndex) and, given ``map_yaml``, 100 robots on that map; with ``baseline``
    the brute-force caster's rate beside each unindexed one."""
    runs = [
        ("1x150", furnished_scene(150, 1, robot_radius), False),
        ("100x150+discs", furnished_scene(150, 100, robot_radius), False),
        ("1x5000", furnished_scene(5000, 1, robot_radius), False),
        ("1x5000 indexed", furnished_scene(5000, 1, robot_radius), True),
    ]
    if map_yaml is not None:
        runs.append(("map 100 indexed", map_scene(map_yaml, 100, robot_radius), True))
    rows = []
    for name, scene, indexed in runs:
        rate = rays_per_second(scene, beams, range_max, indexed=indexed, min_seconds=min_seconds)
        ref = (
            rays_per_second(scene, beams, range_max, reference=True, min_seconds=min_seconds)
            if baseline and not indexed
            else None
        )
        rows.append(
            {
                "config": name,
                "robots": int(scene.origins.shape[0]),
                "beams": beams,
                "segments": int(scene.segments.shape[0]),
                "discs": int(scene.discs.shape[0]),
                "indexed": indexed,
                "rays_per_s": rate,
                "baseline_rays_per_s": ref,
                "speedup": rate / ref if ref else None,
            }
        )
    return rows
