"""``explore.png`` and ``explore.svg``: what an exploration did, drawn with matplotlib.

Left, the merged map the fleet stored (free floor white, walls and furniture black, unknown
grey), each robot's true track in its live-view colour (``fleet.colours``) from its start (a
dot) to its end (a square), and the frontier goals the market sold it: a ring in the robot's
colour where it reached one, a cross where one vanished before it got there or could not be
reached. Right, the map growing: the known area (m²) and the frontiers found over sim time
(explore.json's ``growth``). The figures (status, sim time, IoU, walls within 5 cm) head it.

The SVG keeps its text as text and its artists named: each robot's track ``track-<robot>``,
its goals ``goals-<robot>``, the growth curves ``growth-known`` and ``growth-frontiers``.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import MaxNLocator

from fleet.colours import robot_colour
from fleet.report.summary import ReportError
from planners.grid import GridMap

EXPLORE_FIGURE = "explore"
DPI = 100
FREE_GREY, WALL_GREY, UNKNOWN_GREY = 1.0, 0.0, 0.78


@dataclass(frozen=True)
class FrontierGoal:
    """A frontier task's goal (world metres), the robot it was last sold to ("" if none) and
    its final state (``done``: reached; ``gone``: vanished; ``unreachable``; ...)."""

    task: str
    robot: str
    x: float
    y: float
    state: str


def frontier_goals(state: Path) -> list[FrontierGoal]:
    """The frontier tasks of the coordinator's SQLite ``state`` (read-only), each with the
    robot its last award went to."""
    db = sqlite3.connect(f"file:{state}?mode=ro", uri=True)
    try:
        tasks = db.execute(
            "SELECT id, path, state FROM tasks WHERE kind = 'frontier' ORDER BY id"
        ).fetchall()
        awards = db.execute(
            "SELECT task, robot FROM events WHERE kind = 'awarded' ORDER BY seq"
        ).fetchall()
    finally:
        db.close()
    owner = dict(awards)
    out = []
    for tid, path, st in tasks:
        x, y = np.frombuffer(path, dtype="<f8").reshape(-1, 2)[0]
        out.append(FrontierGoal(str(tid), owner.get(tid, ""), float(x), float(y), str(st)))
    return out


def map_grey(grid: GridMap) -> np.ndarray:
    """The map as grey levels (row 0 at the bottom): free white, occupied black, unknown
    grey."""
    grey = np.full(grid.shape, UNKNOWN_GREY)
    grey[grid.free] = FREE_GREY
    grey[grid.occupied] = WALL_GREY
    return grey


def explore_figure(
    grid: GridMap,
    tracks: Mapping[str, np.ndarray],
    goals: Sequence[FrontierGoal],
    growth: Sequence[Sequence[float]],
    title: str,
) -> Figure:
    """The figure (see the module): ``tracks`` per robot rows (sim s, x, y), ``growth`` rows
    [sim s, known m², frontiers]."""
    rows, cols = grid.shape
    res, (x0, y0) = grid.resolution, grid.origin
    width_m, height_m = cols * res, rows * res
    map_w = 7.0
    map_h = max(3.5, map_w * height_m / width_m)
    fig = Figure(figsize=(map_w + 4.2, map_h + 0.9), dpi=DPI)
    share = map_w / (map_w + 4.2)
    ax = fig.add_axes((0.01, 0.03, share - 0.02, 1 - 0.9 / (map_h + 0.9) - 0.03))
    ax.imshow(
        map_grey(grid),
        cmap="gray",
        vmin=0.0,
        vmax=1.0,
        origin="lower",
        extent=(x0, x0 + width_m, y0, y0 + height_m),
        interpolation="nearest",
    )
    ax.set_aspect("equal")
    ax.set_axis_off()
    handles: list[Line2D] = []
    for rid in sorted(set(tracks) | {g.robot for g in goals if g.robot}):
        colour = robot_colour(rid)
        handles.append(Line2D([], [], color=colour, lw=2, label=rid))
        track = tracks.get(rid)
        if track is not None and len(track):
            ax.plot(track[:, 1], track[:, 2], color=colour, lw=1.4, gid=f"track-{rid}")
            ax.plot(*track[0, 1:], marker="o", ms=6, color=colour, mec="white")
            ax.plot(*track[-1, 1:], marker="s", ms=6, color=colour, mec="white")
        mine = [g for g in goals if g.robot == rid]
        if mine:
            reached = [g.state == "done" for g in mine]
            ax.scatter(
                [g.x for g in mine],
                [g.y for g in mine],
                s=[70 if r else 45 for r in reached],
                marker="o",
                facecolors="none",
                edgecolors=colour,
                linewidths=1.8,
                gid=f"goals-{rid}",
                zorder=4,
            )
            missed = [g for g, r in zip(mine, reached, strict=True) if not r]
            if missed:
                ax.scatter(
                    [g.x for g in missed],
                    [g.y for g in missed],
                    s=35,
                    marker="x",
                    color=colour,
                    zorder=5,
                )
    handles += [
        Line2D(
            [],
            [],
            ls="",
            marker="o",
            ms=8,
            mfc="none",
            mec="grey",
            mew=1.8,
            label="frontier goal reached",
        ),
        Line2D([], [], ls="", marker="x", ms=7, color="grey", label="goal gone or unreachable"),
        Line2D([], [], ls="", marker="o", color="grey", mec="white", label="start"),
        Line2D([], [], ls="", marker="s", color="grey", mec="white", label="end"),
    ]
    fig.legend(handles=handles, loc="upper left", bbox_to_anchor=(share + 0.01, 0.95), fontsize=8)
    _growth_axes(fig, share, growth)
    fig.suptitle(title, fontsize=11)
    return fig


def _growth_axes(fig: Figure, share: float, growth: Sequence[Sequence[float]]) -> None:
    """The known area and the frontiers over sim time, under the legend."""
    ax = fig.add_axes((share + 0.07, 0.1, 0.95 - share - 0.1, 0.38))
    points = np.asarray(growth, dtype=float).reshape(-1, 3)
    ax.step(points[:, 0], points[:, 1], where="post", color="black", gid="growth-known")
    ax.set_xlabel("sim time (s)", fontsize=8)
    ax.set_ylabel("known (m²)", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.set_ylim(bottom=0)
    twin = ax.twinx()
    twin.step(
        points[:, 0], points[:, 2], where="post", color="#3182bd", lw=1, gid="growth-frontiers"
    )
    twin.set_ylabel("frontiers", fontsize=8, color="#3182bd")
    twin.tick_params(labelsize=7, colors="#3182bd")
    twin.set_ylim(bottom=0)
    twin.yaxis.set_major_locator(MaxNLocator(integer=True))


def title_of(report: Mapping[str, Any]) -> str:
    """The figure's title from explore.json: status, sim time, known area, IoU, walls."""
    return (
        f"{report['world']}: {report['status']} in {report['sim_s']:.0f} s sim, "
        f"{report['known_m2']:.1f} m² known, free-space IoU {report['free_iou']:.3f}, "
        f"walls within 5 cm {100 * report['walls_within']:.1f} %"
    )


def render_explore(
    run_dir: Path, grid: GridMap, tracks: Mapping[str, np.ndarray], report: Mapping[str, Any]
) -> list[Path]:
    """Draw ``explore.png`` and ``explore.svg`` into ``run_dir`` from the run's merged map
    ``grid``, true ``tracks``, its explore.json ``report`` and its coordinator state; the files
    written."""
    state = run_dir / "coordinator.sqlite"
    try:
        goals = frontier_goals(state)
    except sqlite3.Error as e:
        raise ReportError(f"{state}: {e}") from None
    with matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": "fleet"}):
        fig = explore_figure(grid, tracks, goals, report["growth"], title_of(report))
        paths = [run_dir / f"{EXPLORE_FIGURE}.png", run_dir / f"{EXPLORE_FIGURE}.svg"]
        for p in paths:
            fig.savefig(p, dpi=DPI, metadata={"Date": None} if p.suffix == ".svg" else None)
    return paths


def redraw_explore(run_dir: Path) -> tuple[dict[str, Any], list[Path]]:
    """Draw an exploration run's pictures again from what it wrote (explore.json, map.yaml,
    tracks.csv, coordinator.sqlite); its explore.json and the files written. A missing or
    damaged file raises ``ReportError`` naming it."""
    from fleet.config import ConfigError
    from fleet.coordinator.exploring import MAP_YAML
    from fleet.report.exploration import EXPLORE_REPORT
    from fleet.report.summary import TRACKS_FILE, read_tracks
    from fleet.rundir import read_json_object
    from fleet.world import load_ros_map

    report = read_json_object(run_dir / EXPLORE_REPORT, ReportError)
    missing = [
        k
        for k in ("world", "status", "sim_s", "known_m2", "free_iou", "walls_within", "growth")
        if k not in report
    ]
    if missing:
        raise ReportError(f"{run_dir / EXPLORE_REPORT}: missing field {missing[0]}")
    try:
        grid = load_ros_map(run_dir / MAP_YAML)
    except (ConfigError, OSError) as e:
        raise ReportError(str(e)) from None
    return report, render_explore(run_dir, grid, read_tracks(run_dir / TRACKS_FILE), report)
