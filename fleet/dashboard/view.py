"""The dashboard's picture of a :class:`~fleet.dashboard.model.FleetSnapshot`: pure functions from
the snapshot (and a screen size) to lines of styled text, with no terminal, bus or clock
behind them. A line is a list of (text, rich style) runs; :func:`plain` turns lines into a
string, :class:`AnsiWriter` into terminal output. Building the
lines by hand instead of through rich's tables keeps a redraw at about a millisecond, so the
view costs a fraction of what it watches (see ``fleet bench dashboard``).

The map is drawn one character per ``sx`` × ``2·sx`` metres (terminal cells are about twice as
tall as wide), so the floor keeps its proportions:

* ``█`` walls and furniture (occupied cells of the coordinator's floor plan),
* ``·`` floor not cleaned yet, ``░`` cleaned floor (the simulator's ground truth),
* an arrow (``→ ↗ ↑ ↖ ← ↙ ↓ ↘``) for each robot's heading, its number beside it, both in its
  colour; ``x`` for a lost robot,
* ``•`` the path each robot means to drive next (its published intent).

While the fleet explores (phase ``exploring``), the floor plan is the robots' merged map as it
grows: only what they have mapped is drawn (floor, walls, and the floor swept on the way), the
unknown stays blank, and ``◎`` in a robot's colour marks the frontier it heads for (the end of
its plan).
"""

from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from rich.color import ColorSystem
from rich.style import Style

from fleet.colours import robot_colour
from fleet.dashboard.model import EXPLORING, FleetSnapshot, RobotRow, dropped_text

Line = list[tuple[str, str]]

ARROWS = "→↗↑↖←↙↓↘"
LOST_MARK = "x"
WALL, DIRTY, CLEANED, PATH, GOAL = "█", "·", "░", "•", "◎"
# a block of cells counts as cleaned when at least this share of its cleanable cells is
CLEANED_SHARE = 0.5
# rows the view gives to everything but the map, besides one per robot
EVENT_ROWS = 6
RATE_ROWS = 6
MIN_MAP_ROWS = 6
BAR_WIDTH = 20
EVENT_STYLES = {
    "lost": "bold red",
    "contact": "yellow",
    "gave up": "yellow",
    "joined": "green",
    "rejoined": "green",
    "placed": "green",
    "unplaced": "yellow",
    "reassigned": "cyan",
    "reopened": "cyan",
    "withdrawn": "cyan",
    "finished": "bold green",
    "error": "red",
    "action": "bold",
}
LIVENESS_STYLES = {"alive": "green", "silent": "yellow", "lost": "bold red", "unknown": "dim"}


def robot_number(rid: str, fallback: int) -> int:
    """The number at the end of a robot id (``robot-3`` → 3), else ``fallback``."""
    m = re.search(r"(\d+)$", rid)
    return int(m.group(1)) if m else fallback


@dataclass(frozen=True)
class MapFrame:
    """Where the world is on the map: the world point (``x0``, ``y_top``) is the top-left
    corner of character (0, 0); each character is ``sx`` m wide and ``2·sx`` m tall."""

    x0: float
    y_top: float
    sx: float
    rows: int
    cols: int

    @property
    def sy(self) -> float:
        return 2.0 * self.sx

    def cell(self, x: float, y: float) -> tuple[int, int] | None:
        """The (row, col) of the character holding world point (x, y), or None off the map."""
        col = math.floor((x - self.x0) / self.sx)
        row = math.floor((self.y_top - y) / self.sy)
        if 0 <= row < self.rows and 0 <= col < self.cols:
            return row, col
        return None

    def cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rows, cols and an inside-the-map mask for (n, 2) world points."""
        col = np.floor((xy[:, 0] - self.x0) / self.sx).astype(np.int64)
        row = np.floor((self.y_top - xy[:, 1]) / self.sy).astype(np.int64)
        inside = (row >= 0) & (row < self.rows) & (col >= 0) & (col < self.cols)
        return row, col, inside


def map_bounds(snap: FleetSnapshot) -> tuple[float, float, float, float] | None:
    """(xmin, ymin, xmax, ymax) of what the map shows: the known cells of the floor plan,
    else the cleanable area (not while exploring: the robots have not mapped it), else the
    robots; None when there is nothing to show yet."""
    if snap.floor is not None:
        g = snap.floor
        known = ~g.unknown
        if known.any():
            rows, cols = np.nonzero(known)
            r = g.resolution
            return (
                g.origin[0] + cols.min() * r,
                g.origin[1] + rows.min() * r,
                g.origin[0] + (cols.max() + 1) * r,
                g.origin[1] + (rows.max() + 1) * r,
            )
    c = snap.cleaned
    if c is not None and c.cleanable.any() and snap.phase != EXPLORING:
        rows, cols = np.nonzero(c.cleanable.reshape(c.rows, c.cols))
        r = c.resolution
        return (
            c.origin_x + cols.min() * r,
            c.origin_y + rows.min() * r,
            c.origin_x + (cols.max() + 1) * r,
            c.origin_y + (rows.max() + 1) * r,
        )
    poses = [r.pose for r in snap.robots if r.pose is not None]
    if poses:
        xs, ys = [p[0] for p in poses], [p[1] for p in poses]
        return min(xs) - 1.0, min(ys) - 1.0, max(xs) + 1.0, max(ys) + 1.0
    return None


def map_frame(bounds: tuple[float, float, float, float], width: int, height: int) -> MapFrame:
    """The largest scale at which ``bounds`` fit ``width`` × ``height`` characters."""
    xmin, ymin, xmax, ymax = bounds
    w, h = max(xmax - xmin, 1e-6), max(ymax - ymin, 1e-6)
    sx = max(w / max(width, 1), h / (2.0 * max(height, 1)))
    cols = min(width, max(1, math.ceil(w / sx - 1e-9)))
    rows = min(height, max(1, math.ceil(h / (2.0 * sx) - 1e-9)))
    return MapFrame(xmin, ymax, sx, rows, cols)


def _grid_blocks(
    frame: MapFrame, shape: tuple[int, int], resolution: float, origin: tuple[float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """For each cell of a grid: the flat index of the map character holding its centre, and
    whether it is on the map at all."""
    rows, cols = shape
    xs = origin[0] + (np.arange(cols) + 0.5) * resolution
    ys = origin[1] + (np.arange(rows) + 0.5) * resolution
    ccol = np.floor((xs - frame.x0) / frame.sx).astype(np.int64)
    crow = np.floor((frame.y_top - ys) / frame.sy).astype(np.int64)
    ok = ((crow >= 0) & (crow < frame.rows))[:, None] & ((ccol >= 0) & (ccol < frame.cols))[None]
    flat = crow[:, None] * frame.cols + ccol[None, :]
    return np.where(ok, flat, 0), ok


def base_layer(snap: FleetSnapshot, frame: MapFrame) -> np.ndarray:
    """The map's characters without robots: walls, floor cleaned or not, blank outside (and,
    while exploring, where the floor plan is unknown)."""
    n = frame.rows * frame.cols
    chars = np.full(n, " ", dtype="<U1")
    if snap.floor is not None:
        g = snap.floor
        flat, ok = _grid_blocks(frame, g.shape, g.resolution, g.origin)
        free = np.bincount(flat[ok & g.free], minlength=n) > 0
        chars[free] = DIRTY
    if snap.cleaned is not None:
        c = snap.cleaned
        flat, ok = _grid_blocks(frame, (c.rows, c.cols), c.resolution, (c.origin_x, c.origin_y))
        cleanable = c.cleanable.reshape(c.rows, c.cols).astype(bool) & ok
        visited = cleanable & c.swept()
        total = np.bincount(flat[cleanable], minlength=n)
        done = np.bincount(flat[visited], minlength=n)
        if snap.phase != EXPLORING:
            chars[(total > 0) & (chars == " ")] = DIRTY
        chars[(total > 0) & (done >= CLEANED_SHARE * total)] = CLEANED
    if snap.floor is not None:
        g = snap.floor
        flat, ok = _grid_blocks(frame, g.shape, g.resolution, g.origin)
        chars[np.bincount(flat[ok & g.occupied], minlength=n) > 0] = WALL
    return chars.reshape(frame.rows, frame.cols)


class _Memo:
    """The last value made from the same objects (by identity) and the same frame: the floor
    plan and the cleaned area change once a second at most, the view redraws five times, and
    a large map costs milliseconds to lay out."""

    def __init__(self) -> None:
        self._objects: tuple[object, ...] | None = None
        self._frame: MapFrame | None = None
        self._value: Any = None

    def get(self, objects: tuple[object, ...], frame: MapFrame | None, make: Any) -> Any:
        if (
            self._objects is None
            or frame != self._frame
            or any(a is not b for a, b in zip(objects, self._objects, strict=True))
        ):
            self._value = make()
            self._objects, self._frame = objects, frame
        return self._value


_BOUNDS = _Memo()
_BASE = _Memo()


def heading_arrow(theta: float) -> str:
    """The arrow nearest to heading ``theta`` (rad, 0 = +x, counter-clockwise)."""
    return ARROWS[round(theta / (math.pi / 4)) % 8]


BASE_STYLES = {WALL: "grey70", DIRTY: "grey37", CLEANED: "green4", " ": ""}


def render_map(
    snap: FleetSnapshot, width: int, height: int, selected: str | None = None
) -> list[Line]:
    """The floor, its cleaned area, each robot's path ahead and each robot's marker, in at
    most ``width`` × ``height`` characters (see the module docstring)."""
    # what the base layer is drawn from (by identity: EXPLORING, not the snapshot's own string)
    layers = (snap.floor, snap.cleaned, EXPLORING if snap.phase == EXPLORING else None)
    if snap.floor is None and snap.cleaned is None:
        bounds = map_bounds(snap)
    else:
        bounds = _BOUNDS.get(layers, None, lambda: map_bounds(snap))
    if bounds is None or width < 4 or height < 2:
        return [[("(waiting for the floor plan and the robots' poses)", "dim")]]
    frame = map_frame(bounds, width, height)
    chars = _BASE.get(layers, frame, lambda: base_layer(snap, frame)).copy()
    styles = np.empty(chars.shape, dtype=object)
    for ch, style in BASE_STYLES.items():
        styles[chars == ch] = style
    for robot in snap.robots:
        if robot.intent is None or len(robot.intent) == 0 or robot.liveness == "lost":
            continue
        rows, cols, inside = frame.cells(np.asarray(robot.intent, dtype=float))
        chars[rows[inside], cols[inside]] = PATH
        styles[rows[inside], cols[inside]] = robot_colour(robot.rid)
    if snap.phase == EXPLORING:
        for robot in snap.robots:
            at = None if robot.goal is None else frame.cell(*robot.goal)
            if at is not None and robot.liveness != "lost":
                chars[at], styles[at] = GOAL, f"bold {robot_colour(robot.rid)}"
    for i, robot in enumerate(snap.robots):
        _place_marker(chars, styles, frame, robot, i, robot.rid == selected)
    return _runs(chars, styles)


def _place_marker(
    chars: np.ndarray,
    styles: np.ndarray,
    frame: MapFrame,
    robot: RobotRow,
    index: int,
    selected: bool,
) -> None:
    if robot.pose is None:
        return
    at = frame.cell(robot.pose[0], robot.pose[1])
    if at is None:
        return
    row, col = at
    lost = robot.liveness == "lost"
    colour = "bold red" if lost else f"bold {robot_colour(robot.rid)}"
    style = f"{colour} reverse" if selected else colour
    chars[row, col] = LOST_MARK if lost else heading_arrow(robot.pose[2])
    styles[row, col] = style
    label = str(robot_number(robot.rid, index))
    start = col + 1 if col + len(label) < frame.cols else col - len(label)
    for j, ch in enumerate(label):
        c = start + j
        if 0 <= c < frame.cols:
            chars[row, c] = ch
            styles[row, c] = style


def _runs(chars: np.ndarray, styles: np.ndarray) -> list[Line]:
    lines = []
    for r in range(chars.shape[0]):
        row_chars, row_styles = chars[r], styles[r]
        line: Line = []
        start = 0
        n = len(row_chars)
        for c in range(1, n + 1):
            if c == n or row_styles[c] != row_styles[start]:
                line.append(("".join(row_chars[start:c]), row_styles[start]))
                start = c
        lines.append(line)
    return lines


def progress_bar(fraction: float, width: int = BAR_WIDTH) -> str:
    """``[#########-----------]`` for a fraction in [0, 1]."""
    filled = round(max(0.0, min(1.0, fraction)) * width)
    return "[" + "#" * filled + "-" * (width - filled) + "]"


def duration(seconds: float) -> str:
    """``45 s``, ``3 min 05 s``, ``1 h 02 min``."""
    s = round(seconds)
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {(s % 3600) // 60:02d} min"


def header(snap: FleetSnapshot) -> Line:
    """The view's note (if any), phase, coverage with its bar, the ETA, tasks, sim time,
    repetition, contacts and the messages processes dropped on one line, most wanted first (a
    narrow terminal cuts the end)."""
    cov = snap.coverage or 0.0
    parts = [f"fleet {snap.fleet}", snap.phase]
    parts.append(f"coverage {progress_bar(cov)} {100 * cov:4.1f} %")
    if snap.eta_s is not None:
        finished = snap.phase in ("done", "incomplete")
        parts.append(snap.phase if finished else f"ETA {duration(snap.eta_s)}")
    if snap.tasks is not None:
        o, a, d = snap.tasks
        parts.append(f"tasks {d}/{o + a + d + snap.left_out} done")
    if snap.left_out:
        parts.append(f"{snap.left_out} out of reach")
    parts.append(f"sim {snap.sim_time:.1f} s")
    if snap.repetition is not None:
        parts.append(f"repetition {100 * snap.repetition:.1f} %")
    if snap.collisions:
        parts.append(f"contacts {snap.collisions}")
    line: Line = [(" · ".join(parts), "bold")]
    dropped = dropped_text(snap.dropped)
    if dropped:
        line.append((f" · dropped: {dropped}", "bold yellow"))
    if snap.note:
        line.insert(0, (f"{snap.note} · ", "bold yellow"))
    return line


# (title, width, right-aligned)
ROBOT_COLUMNS = (
    ("robot", 12, False),
    ("live", 7, False),
    ("state", 10, False),
    ("task", 8, False),
    ("progress", 8, True),
    ("m/s", 5, True),
    ("heartbeat", 9, True),
    ("restarts", 8, True),
    ("gave up", 7, True),
    ("battery", 8, True),
)


def _cell(text: str, width: int, right: bool) -> str:
    text = text[:width]
    return text.rjust(width) if right else text.ljust(width)


def robot_table(snap: FleetSnapshot, selected: str | None = None) -> list[Line]:
    """A title row, then one row per robot: liveness, state, task, progress, speed, heartbeat
    age, restarts, waypoints given up and charge; the selected robot's row reversed."""
    title = " ".join(_cell(name, w, right) for name, w, right in ROBOT_COLUMNS)
    lines: list[Line] = [[(title, "bold")]]
    for r in snap.robots:
        values = (
            f"{heading_arrow(r.pose[2]) if r.pose else ' '} {r.rid}",
            r.liveness,
            r.state or "—",
            r.task or "—",
            "—" if r.progress is None else f"{100 * r.progress:5.1f} %",
            f"{r.speed:4.2f}",
            "—" if r.heartbeat_age is None else f"{r.heartbeat_age:4.1f} s",
            "—" if r.restarts is None else str(r.restarts),
            str(r.gave_up),
            battery_cell(r.charge, r.charging),
        )
        cells = [_cell(v, w, right) for v, (_, w, right) in zip(values, ROBOT_COLUMNS, strict=True)]
        rev = " reverse" if r.rid == selected else ""
        line: Line = [(cells[0], f"{robot_colour(r.rid)}{rev}"), (" ", rev.strip())]
        line.append((cells[1], f"{LIVENESS_STYLES.get(r.liveness, '')}{rev}".strip()))
        line.append((" " + " ".join(cells[2:]), rev.strip()))
        lines.append(line)
    return lines


def battery_cell(charge: float | None, charging: bool) -> str:
    """A robot's charge as the table shows it: "—" without batteries, "+" while charging."""
    if charge is None:
        return "—"
    return f"{'+' if charging else ''}{100 * charge:.0f} %"


def events_panel(snap: FleetSnapshot, rows: int = EVENT_ROWS) -> list[Line]:
    """The newest ``rows`` events, oldest first, coloured by kind."""
    lines = snap.events[-rows:] if rows > 0 else []
    if not lines:
        return [[("(no events yet)", "dim")]]
    return [[(f"{_clock(e.wall)} {e.text}", EVENT_STYLES.get(e.kind, ""))] for e in lines]


def rates_panel(snap: FleetSnapshot, rows: int = RATE_ROWS) -> list[Line]:
    """Messages per second on the keys the dashboard reads, busiest first."""
    shown = [(k, r) for k, r in snap.rates if r > 0][:rows]
    if not shown:
        return [[("(no messages yet)", "dim")]]
    return [[(f"{rate:7.1f}/s  {key}", "")] for key, rate in shown]


def _clock(wall: float) -> str:
    return time.strftime("%H:%M:%S", time.localtime(wall))


def fit(line: Line, width: int) -> Line:
    """``line`` cut or padded with spaces to exactly ``width`` characters."""
    out: Line = []
    left = width
    for text, style in line:
        if left <= 0:
            break
        out.append((text[:left], style))
        left -= min(len(text), left)
    if left > 0:
        out.append((" " * left, ""))
    return out


def beside(left: list[Line], right: list[Line], left_width: int, width: int) -> list[Line]:
    """Two columns of lines: ``left`` in ``left_width`` characters, then ``right``."""
    rows = max(len(left), len(right))
    out = []
    for i in range(rows):
        a = fit(left[i], left_width) if i < len(left) else [(" " * left_width, "")]
        b = right[i] if i < len(right) else []
        out.append(fit(a + b, width))
    return out


def screen(
    snap: FleetSnapshot,
    width: int,
    height: int,
    selected: str | None = None,
    footer: str = "",
) -> list[Line]:
    """The whole view for a ``width`` × ``height`` terminal: header, map, robot table, then
    events beside message rates, and ``footer`` (the keys); every line exactly ``width``."""
    fixed = 1 + (len(snap.robots) + 1) + EVENT_ROWS + (1 if footer else 0)
    map_rows = max(MIN_MAP_ROWS, height - fixed)
    rates_width = min(40, width // 3)
    lines = [header(snap)]
    lines += render_map(snap, width, map_rows, selected)
    lines += robot_table(snap, selected)
    lines += beside(events_panel(snap), rates_panel(snap), width - rates_width, width)
    if footer:
        lines.append([(footer, "dim")])
    return [fit(line, width) for line in lines[:height]]


def plain(lines: list[Line]) -> str:
    """The lines' characters without styles."""
    return "\n".join("".join(text for text, _ in line).rstrip() for line in lines)


COLOR_SYSTEMS = {
    "standard": ColorSystem.STANDARD,
    "256": ColorSystem.EIGHT_BIT,
    "truecolor": ColorSystem.TRUECOLOR,
    "windows": ColorSystem.WINDOWS,
}


class AnsiWriter:
    """Frames of lines to a terminal's alternate screen as ANSI text: the cursor goes home,
    each line is written and cleared to its end, then the rest of the screen is cleared.
    ``color_system`` as rich names it (None: no colours)."""

    def __init__(self, color_system: str | None) -> None:
        self.color_system = COLOR_SYSTEMS.get(color_system or "")
        self._codes: dict[str, tuple[str, str]] = {}

    def _style(self, style: str) -> tuple[str, str]:
        codes = self._codes.get(style)
        if codes is None:
            if not style or self.color_system is None:
                codes = ("", "")
            else:
                before, _, after = (
                    Style.parse(style).render("\0", color_system=self.color_system).partition("\0")
                )
                codes = (before, after)
            self._codes[style] = codes
        return codes

    def frame(self, lines: list[Line]) -> str:
        out = ["\x1b[H"]
        for line in lines:
            for text, style in line:
                before, after = self._style(style)
                out.append(f"{before}{text}{after}")
            out.append("\x1b[K\r\n")
        if out[-1] == "\x1b[K\r\n":
            out[-1] = "\x1b[K"
        out.append("\x1b[J")
        return "".join(out)
