"""The report's pictures, drawn with matplotlib from a run dir's data (``fleet.report.summary``).

* ``report.png`` and ``report.svg``: the floor with its cleaned cells shaded by passes, the
  missed cleanable cells in red, each robot's true track in its live-view colour
  (``fleet.colours``) labelled with its id, a scale bar in metres, a legend, and the run's
  figures.
* ``coverage.png`` and ``coverage.svg``: coverage over sim time, the fleet's (as the simulator
  measured it) and each robot's (the cleanable floor its own brush swept, from its track), with
  the job's events marked on the robot they concern.

The SVGs keep their text as text, so ids and legends can be searched; the legend, the scale bar
and each robot's label carry ids (``legend``, ``scale-bar``, ``label-<robot>``).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib
import matplotlib.colors
import numpy as np
from matplotlib.artist import Artist
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Rectangle

from fleet.colours import robot_colour
from fleet.report.summary import RunData

DPI = 100
MAP_WIDTH_IN = 7.0
SIDE_WIDTH_IN = 3.4
MIN_MAP_HEIGHT_IN = 4.0
# cleaned cells by passes: 1, 2, 3, 4 or more
PASS_COLOURS = ("#c7e9c0", "#74c476", "#31a354", "#006d2c")
MISSED_COLOUR = "#e34a33"
# floor only a side brush touched (the main brush never passed over it)
SIDE_COLOUR = "#9ecae1"
BLOCKED_COLOUR = "#4d4d4d"
# the paths of work no robot could reach (report.json's left_out), dashed over the floor
LEFT_OUT_COLOUR = "#000000"
SCALE_BAR_COLOUR = "#000000"
# the scale bar is the longest of these not longer than this share of the floor's width
SCALE_BAR_LENGTHS_M = (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0)
SCALE_BAR_SHARE = 0.3
# the margin under the floor that holds the scale bar, in floor widths, and the bar's thickness
SCALE_MARGIN_SHARE = 0.12
SCALE_BAR_THICKNESS_SHARE = 0.012
# events drawn on the timeline, and how; the routine ones (awards, auctions, plans) are only
# in report.json
EVENT_MARKERS = {
    "joined": ("^", "joined"),
    "rejoined": ("v", "rejoined"),
    "lost": ("X", "lost"),
    "reassigned": ("D", "got a lost robot's work"),
    "reopened": ("s", "work reopened"),
    "withdrawn": ("P", "work withdrawn"),
    "done": ("|", "task done"),
}
FLEET_EVENTS = ("resumed", "finished", "map changed")
# events drawn above the others when they fall on one spot
EVENT_ZORDER = {"lost": 6, "rejoined": 5, "joined": 5}
# a robot's id label is stacked above those of robots that ended within this distance
LABEL_NEAR_M = 0.8
LABEL_STEP_PT = 14
COLLISION_MARKER = "*"


def render_report(data: RunData) -> list[Path]:
    """Draw every picture into the run dir; returns the files written."""
    out = data.run_dir
    with matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": "fleet"}):
        fig, _ = map_figure(data)
        written = _save(fig, out / "report")
        written += _save(timeline_figure(data), out / "coverage")
    return written


def _save(fig: Figure, stem: Path) -> list[Path]:
    paths = [stem.with_suffix(".png"), stem.with_suffix(".svg")]
    for p in paths:
        fig.savefig(p, dpi=DPI, metadata={"Date": None} if p.suffix == ".svg" else None)
    return paths


def scale_bar_length(width_m: float) -> float:
    """A round length of at most ``SCALE_BAR_SHARE`` of the floor's width (the shortest when
    the floor is narrower than that)."""
    fits = [m for m in SCALE_BAR_LENGTHS_M if m <= SCALE_BAR_SHARE * width_m]
    return fits[-1] if fits else SCALE_BAR_LENGTHS_M[0]


def floor_rgb(
    visits: np.ndarray, cleanable: np.ndarray, side: np.ndarray | None = None
) -> np.ndarray:
    """The floor as RGB (row 0 at the bottom): main brush passes in greens, cleanable cells
    only a side brush touched (``side``) light blue, missed cleanable cells red, the rest
    (walls, furniture, floor out of reach) grey."""
    rgb = np.empty((*visits.shape, 3))
    rgb[:] = matplotlib.colors.to_rgb(BLOCKED_COLOUR)
    rgb[cleanable] = matplotlib.colors.to_rgb(MISSED_COLOUR)
    if side is not None:
        rgb[cleanable & side] = matplotlib.colors.to_rgb(SIDE_COLOUR)
    passes = np.clip(visits, 0, len(PASS_COLOURS))
    for n, colour in enumerate(PASS_COLOURS, start=1):
        rgb[passes == n] = matplotlib.colors.to_rgb(colour)
    return rgb


def map_figure(data: RunData) -> tuple[Figure, float]:
    """The floor, tracks, scale bar, legend and figures; and the scale bar's length in metres."""
    rows, cols = data.visits.shape
    res = data.resolution
    x0, y0 = data.origin
    width_m, height_m = cols * res, rows * res
    margin = SCALE_MARGIN_SHARE * width_m
    map_h = max(MIN_MAP_HEIGHT_IN, MAP_WIDTH_IN * (height_m + margin) / width_m)
    fig = Figure(figsize=(MAP_WIDTH_IN + SIDE_WIDTH_IN, map_h + 0.8), dpi=DPI)
    left = 0.02
    map_frac = MAP_WIDTH_IN / (MAP_WIDTH_IN + SIDE_WIDTH_IN)
    ax = fig.add_axes((left, 0.02, map_frac - left, 1 - 0.8 / (map_h + 0.8) - 0.02))
    ax.imshow(
        floor_rgb(data.visits, data.cleanable, data.side),
        origin="lower",
        extent=(x0, x0 + width_m, y0, y0 + height_m),
        interpolation="nearest",
    )
    ax.set_xlim(x0, x0 + width_m)
    ax.set_ylim(y0 - margin, y0 + height_m)
    ax.set_aspect("equal")
    ax.set_axis_off()
    handles: list[Artist] = []
    lost = lost_at_end(data)
    ends: list[np.ndarray] = []
    for rid in data.robots:
        colour = robot_colour(rid)
        track = data.tracks.get(rid)
        length = data.report["robots"].get(rid, {}).get("path_length_m")
        label = rid if length is None else f"{rid} ({length:.1f} m)"
        handles.append(Line2D([], [], color=colour, lw=2, label=label))
        if track is None or len(track) == 0:
            continue
        ax.plot(track[:, 1], track[:, 2], color=colour, lw=1.6, solid_capstyle="round")
        ax.plot(*track[0, 1:], marker="o", ms=6, color=colour, mec="white")
        end = track[-1, 1:]
        if rid in lost:
            ax.plot(*end, marker="X", ms=11, color=colour, mec="black", zorder=5)
        else:
            ax.plot(*end, marker="s", ms=6, color=colour, mec="white")
        # labels of robots that ended close together are stacked, not drawn over each other
        stacked = sum(np.hypot(*(end - e)) < LABEL_NEAR_M for e in ends)
        ends.append(end)
        text = ax.annotate(
            rid,
            end,
            xytext=(6, 6 + LABEL_STEP_PT * stacked),
            textcoords="offset points",
            color=colour,
            fontsize=9,
            fontweight="bold",
            bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": colour, "alpha": 0.85},
        )
        text.set_gid(f"label-{rid}")
    for c in data.collisions:
        ax.plot(c["x"], c["y"], marker="x", ms=8, mew=2, color="black")
    left_out = data.report.get("left_out") or []
    for piece in left_out:
        path = np.asarray(piece["path"], dtype=float).reshape(-1, 2)
        line = ax.plot(
            path[:, 0], path[:, 1], color=LEFT_OUT_COLOUR, lw=2.2, ls=(0, (3, 2)), zorder=4
        )[0]
        line.set_gid(f"left-out-{piece['id']}")
    bar_m = scale_bar_length(width_m)
    bar_y = y0 - 0.55 * margin
    bar = Rectangle(
        (x0 + 0.03 * width_m, bar_y),
        bar_m,
        SCALE_BAR_THICKNESS_SHARE * width_m,
        facecolor=SCALE_BAR_COLOUR,
        edgecolor="none",
        antialiased=False,
    )
    bar.set_gid("scale-bar")
    ax.add_patch(bar)
    ax.text(
        x0 + 0.03 * width_m + bar_m / 2,
        bar_y - 0.08 * margin,
        f"{bar_m:g} m",
        ha="center",
        va="top",
        fontsize=9,
    )
    missed_m2 = float((data.cleanable & ~data.swept).sum()) * res * res
    side_m2 = float((data.cleanable & data.swept & (data.visits == 0)).sum()) * res * res
    if side_m2 > 0:
        handles.append(Patch(color=SIDE_COLOUR, label=f"side brush only ({side_m2:.2f} m²)"))
    handles += [
        Patch(color=PASS_COLOURS[0], label="cleaned once"),
        Patch(color=PASS_COLOURS[1], label="cleaned twice"),
        Patch(color=PASS_COLOURS[2], label="cleaned 3 times"),
        Patch(color=PASS_COLOURS[3], label="cleaned 4+ times"),
        Patch(color=MISSED_COLOUR, label=f"missed ({missed_m2:.2f} m²)"),
        Patch(color=BLOCKED_COLOUR, label="wall, furniture, out of reach"),
        Line2D([], [], ls="", marker="o", color="grey", mec="white", label="start"),
        Line2D([], [], ls="", marker="s", color="grey", mec="white", label="end"),
    ]
    if lost:
        handles.append(
            Line2D([], [], ls="", marker="X", ms=9, color="grey", mec="black", label="lost there")
        )
    if data.collisions:
        handles.append(Line2D([], [], ls="", marker="x", mew=2, color="black", label="contact"))
    if left_out:
        area = sum(p["area_m2"] for p in left_out)
        handles.append(
            Line2D(
                [],
                [],
                color=LEFT_OUT_COLOUR,
                lw=2.2,
                ls=(0, (3, 2)),
                label=f"not reached ({area:.2f} m²)",
            )
        )
    legend = fig.legend(
        handles=handles, loc="upper left", bbox_to_anchor=(map_frac + 0.01, 0.9), fontsize=8
    )
    legend.set_gid("legend")
    fig.text(
        map_frac + 0.02,
        0.02,
        _figures_text(data),
        va="bottom",
        ha="left",
        fontsize=8,
        family="monospace",
    )
    fig.suptitle(_title(data), fontsize=12)
    return fig, bar_m


def _title(data: RunData) -> str:
    r = data.report
    world = Path(str(r.get("world", "?"))).stem
    return (
        f"fleet run {data.run_dir.name}: {world}, {len(data.robots)} robots, {r['status']} — "
        f"coverage {100 * r['coverage']:.1f} %"
    )


def _figures_text(data: RunData) -> str:
    r = data.report
    makespan = r.get("makespan_s")
    lines = [
        f"coverage      {100 * r['coverage']:6.1f} %",
        f"repetition    {100 * r['repetition']:6.1f} %",
        f"cleanable     {r['cleanable_m2']:6.2f} m²",
        "makespan      " + ("   not done" if makespan is None else f"{makespan:6.1f} s sim"),
        f"sim time      {r['sim_time_s']:6.1f} s",
        f"wall time     {r['wall_s']:6.1f} s",
        f"contacts      {r['collisions'].get('robot_wall', 0)} wall, "
        f"{r['collisions'].get('robot_robot', 0)} robot",
    ]
    events = data.events
    lost = sum(e["kind"] == "lost" for e in events)
    if events:
        lines.append(f"robots lost   {lost}")
    if r.get("left_out"):
        lines.append(f"not reached   {r['left_out_m2']:6.2f} m²")
    return "\n".join(lines)


def lost_at_end(data: RunData) -> set[str]:
    """The robots whose last liveness event is ``lost`` (no ``joined`` or ``rejoined`` after)."""
    last: dict[str, str] = {}
    for e in data.events:
        if e["kind"] in ("lost", "joined", "rejoined"):
            last[e["robot"]] = e["kind"]
    return {rid for rid, kind in last.items() if kind == "lost"}


def swept_over_time(data: RunData, robot: str) -> tuple[np.ndarray, np.ndarray]:
    """Sim times and the share of the cleanable floor ``robot``'s brush had swept by then,
    from its true track (a cell is swept when its centre came strictly within half the brush
    width of the track)."""
    track = data.tracks.get(robot)
    total = int(data.cleanable.sum())
    if track is None or len(track) == 0 or total == 0:
        return np.zeros(0), np.zeros(0)
    res = data.resolution
    x0, y0 = data.origin
    rows, cols = data.cleanable.shape
    radius = data.cleaning_width_m / 2
    reach = int(np.ceil(radius / res)) + 1
    swept = np.zeros_like(data.cleanable)
    counts = np.zeros(len(track), dtype=np.int64)
    count = 0
    for i in range(len(track)):
        a = track[max(i - 1, 0), 1:]
        b = track[i, 1:]
        lo = np.floor((np.minimum(a, b) - (x0, y0)) / res).astype(int) - reach
        hi = np.floor((np.maximum(a, b) - (x0, y0)) / res).astype(int) + reach
        c0, r0 = max(lo[0], 0), max(lo[1], 0)
        c1, r1 = min(hi[0], cols - 1), min(hi[1], rows - 1)
        if c0 <= c1 and r0 <= r1:
            cx = x0 + (np.arange(c0, c1 + 1) + 0.5) * res
            cy = y0 + (np.arange(r0, r1 + 1) + 0.5) * res
            px, py = np.meshgrid(cx, cy)
            d = b - a
            den = float(d @ d)
            s = (
                np.zeros_like(px)
                if den == 0
                else np.clip(((px - a[0]) * d[0] + (py - a[1]) * d[1]) / den, 0, 1)
            )
            inside = np.hypot(px - a[0] - s * d[0], py - a[1] - s * d[1]) < radius
            window = swept[r0 : r1 + 1, c0 : c1 + 1]
            fresh = inside & ~window & data.cleanable[r0 : r1 + 1, c0 : c1 + 1]
            count += int(fresh.sum())
            window |= fresh
        counts[i] = count
    return track[:, 0], counts / total


def timeline_figure(data: RunData) -> Figure:
    """Coverage over sim time, the fleet's and each robot's, with the events marked."""
    fig = Figure(figsize=(MAP_WIDTH_IN + SIDE_WIDTH_IN, 5.0), dpi=DPI)
    ax = fig.add_axes((0.07, 0.11, 0.62, 0.78))
    handles: list[Artist] = []
    if len(data.coverage):
        ax.plot(data.coverage[:, 0], 100 * data.coverage[:, 1], color="black", lw=2)
        handles.append(Line2D([], [], color="black", lw=2, label="fleet (simulator)"))
    curves = {}
    for rid in data.robots:
        t, share = swept_over_time(data, rid)
        curves[rid] = (t, 100 * share)
        colour = robot_colour(rid)
        if len(t):
            ax.plot(t, 100 * share, color=colour, lw=1.5)
        handles.append(Line2D([], [], color=colour, lw=1.5, label=f"{rid} (own brush)"))
    kinds_seen: set[str] = set()
    for e in data.events:
        kind, rid, t = e["kind"], e["robot"], float(e["sim"])
        if kind in FLEET_EVENTS:
            ax.axvline(t, color="grey", ls="--", lw=1)
            ax.annotate(
                f"{kind} ",
                (t, 0.02),
                xycoords=("data", "axes fraction"),
                rotation=90,
                fontsize=7,
                ha="right",
                va="bottom",
                color="grey",
            )
            continue
        if kind not in EVENT_MARKERS or rid not in curves:
            continue
        ts, ys = curves[rid]
        y = float(np.interp(t, ts, ys)) if len(ts) else 0.0
        marker = EVENT_MARKERS[kind][0]
        ax.plot(
            t,
            y,
            marker=marker,
            ms=11 if kind == "lost" else 9,
            color=robot_colour(rid),
            mec="black",
            ls="",
            zorder=EVENT_ZORDER.get(kind, 4),
        )
        kinds_seen.add(kind)
    for c in data.collisions:
        rid = c["robot"]
        if rid in curves and len(curves[rid][0]):
            ts, ys = curves[rid]
            ax.plot(
                c["sim_s"],
                float(np.interp(c["sim_s"], ts, ys)),
                marker=COLLISION_MARKER,
                ms=11,
                color="black",
                ls="",
            )
            kinds_seen.add("contact")
    for kind, (marker, label) in EVENT_MARKERS.items():
        if kind in kinds_seen:
            handles.append(
                Line2D([], [], ls="", marker=marker, ms=8, color="white", mec="black", label=label)
            )
    if "contact" in kinds_seen:
        handles.append(
            Line2D([], [], ls="", marker=COLLISION_MARKER, ms=9, color="black", label="contact")
        )
    ax.set_xlabel("sim time (s)")
    ax.set_ylabel("cleanable floor swept (%)")
    ax.set_ylim(0, 102)
    ax.set_xlim(left=0)
    ax.grid(alpha=0.3)
    legend = fig.legend(handles=handles, loc="upper left", bbox_to_anchor=(0.71, 0.89), fontsize=8)
    legend.set_gid("legend")
    fig.suptitle(f"Coverage over time — {_title(data)}", fontsize=11)
    return fig
