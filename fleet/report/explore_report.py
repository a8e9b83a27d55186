"""explore.json of a `fleet explore` run, assembled once its fleet has stopped: how the
exploration ended and what it took, the merged map scored against the world's true floor (the
truth read here only, after the run), and where the robots that did not know their start were
placed; written with map.png and the exploration's figure."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fleet.coordinator.exploring import MAP_PGM, MAP_YAML
from fleet.report.exploration import (
    EXPLORE_REPORT,
    MAP_PNG,
    free_iou,
    frontier_counts,
    growth,
    path_lengths,
    placements,
    plan_floor_lost,
    true_floor,
    walls_within,
    write_map_png,
)
from fleet.report.summary import TRACKS_FILE, read_tracks, write_json
from fleet.world import load_ros_map

if TYPE_CHECKING:
    from fleet.params import FleetConfig
    from fleet.world import World


def explore_report(
    run_dir: Path,
    cfg: FleetConfig,
    world: World,
    start: tuple[float, float, float],
    status: str,
    sim_s: float,
    wall_s: float,
    tracks: dict[str, np.ndarray],
) -> dict[str, Any]:
    """explore.json: how the exploration ended and what it took, and the merged map scored
    against the world's true floor (the truth read here only, after the run): free-space IoU,
    ``walls_within``, the share of the true walls with a mapped wall within 5 cm,
    ``plan_floor``, the floor a cleaning plan on the map loses against one on the world file,
    by cause (``fleet.report.exploration.plan_floor_lost``), and ``growth``, the merged map as
    it grew ([sim s, known m², frontiers] per update)."""
    mapped = load_ros_map(run_dir / MAP_YAML)
    truth, floor = true_floor(world, mapped.resolution, (start[0], start[1]))
    return {
        "status": status,
        "world": world.name,
        "sim_s": round(sim_s, 1),
        "wall_s": round(wall_s, 1),
        "path_length_m": path_lengths(tracks),
        "frontiers": frontier_counts(run_dir / "coordinator.sqlite"),
        "growth": growth(run_dir / "coordinator.sqlite"),
        "known_m2": round(float((mapped.free | mapped.occupied).sum()) * mapped.resolution**2, 2),
        "true_floor_m2": round(float(floor.sum()) * truth.resolution**2, 2),
        "free_iou": round(free_iou(mapped, truth, floor), 4),
        "walls_within": round(walls_within(mapped, truth, floor), 4),
        "plan_floor": plan_floor_lost(
            mapped,
            world,
            (start[0], start[1]),
            cfg.robot.radius + cfg.coordinator.wall_clearance,
            cfg.robot.cleaning_width / 2,
        ),
        "map": MAP_YAML,
    }


def write_explore_report(
    run_dir: Path,
    cfg: FleetConfig,
    world: World,
    starts: Sequence[tuple[float, float, float]],
    unknown_start: int,
    status: str,
    sim_s: float,
    wall_s: float,
) -> dict[str, Any]:
    """Write explore.json (with ``placements`` when the last ``unknown_start`` of the robots
    started at ``starts`` were not told theirs), map.png and the exploration's figure into
    ``run_dir``; explore.json's content."""
    from fleet.report.explore_figure import render_explore

    tracks = read_tracks(run_dir / TRACKS_FILE)
    report = explore_report(run_dir, cfg, world, starts[0], status, sim_s, wall_s, tracks)
    robots = len(starts)
    unknown = {f"robot-{i}": starts[i] for i in range(robots - unknown_start, robots)}
    if unknown:
        report["placements"] = placements(run_dir / "coordinator.sqlite", unknown)
    write_json(run_dir / EXPLORE_REPORT, report)
    write_map_png(run_dir / MAP_PGM, run_dir / MAP_PNG)
    render_explore(run_dir, load_ros_map(run_dir / MAP_YAML), tracks, report)
    return report
