"""MovingAI benchmark formats (Sturtevant 2012; the MAPF suite of Stern et al., SoCS 2019).

``.map``::

    type octile
    height H
    width W
    map
    <H lines of W characters: '.', 'G', 'S' passable; '@', 'O', 'T', 'W' blocked>

``.scen``: an optional ``version N`` line, then one tab-separated line per agent
``bucket  map  width  height  start_x  start_y  goal_x  goal_y  optimal_length`` where x is the
column and y the row counted from the top; an instance with k agents uses the first k lines.
The map name column is informative only (scenarios are often moved away from their maps), and
the last column is an octile (8-connected) distance, so it is kept but never used as a 4-connected
optimum. CRLF line endings are accepted. Errors name the file and the line.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from planners.mapf.model import MapfInstance

PASSABLE = frozenset(".GS")
BLOCKED = frozenset("@OTW")


class FormatError(ValueError):
    """A malformed benchmark file; the message names the file and line."""


@dataclass(frozen=True)
class ScenarioEntry:
    """One scenario line; ``start``/``goal`` are ``(row, col)`` = ``(y, x)``."""

    bucket: int
    map_name: str
    width: int
    height: int
    start: tuple[int, int]
    goal: tuple[int, int]
    optimal_length: float


def _lines(path: Path) -> list[str]:
    try:
        text = path.read_text(encoding="utf-8", errors="strict")
    except UnicodeDecodeError as err:
        raise FormatError(f"{path}: not a text file ({err})") from err
    return [line.rstrip("\r") for line in text.split("\n")]


def parse_map(text_lines: Sequence[str], source: str = "<map>") -> np.ndarray:
    """The passable-cell mask (rows, cols) of a ``.map`` given as lines."""
    header: dict[str, str] = {}
    i = 0
    while i < len(text_lines):
        line = text_lines[i].strip()
        i += 1
        if not line:
            continue
        if line.lower() == "map":
            break
        key, _, value = line.partition(" ")
        if key.lower() not in ("type", "height", "width"):
            raise FormatError(f"{source}:{i}: unexpected header line {line!r}")
        header[key.lower()] = value.strip()
    else:
        raise FormatError(f"{source}: no 'map' line after the header")
    try:
        height, width = int(header["height"]), int(header["width"])
    except KeyError as err:
        raise FormatError(f"{source}: header lacks {err.args[0]!r}") from err
    except ValueError as err:
        raise FormatError(f"{source}: height/width must be integers ({err})") from err
    if height <= 0 or width <= 0:
        raise FormatError(f"{source}: height and width must be positive")
    rows = text_lines[i : i + height]
    if len(rows) < height:
        raise FormatError(f"{source}: {len(rows)} grid lines, header says height {height}")
    free = np.zeros((height, width), dtype=bool)
    for r, row in enumerate(rows):
        lineno = i + r + 1
        if len(row) != width:
            raise FormatError(
                f"{source}:{lineno}: {len(row)} characters, header says width {width}"
            )
        for c, ch in enumerate(row):
            if ch in PASSABLE:
                free[r, c] = True
            elif ch not in BLOCKED:
                raise FormatError(f"{source}:{lineno}: unknown terrain {ch!r} in column {c + 1}")
    return free


def read_map(path: str | Path) -> np.ndarray:
    path = Path(path)
    return parse_map(_lines(path), str(path))


def write_map(path: str | Path, free: np.ndarray) -> None:
    rows, cols = free.shape
    grid = "\n".join("".join("." if v else "@" for v in row) for row in free)
    Path(path).write_text(f"type octile\nheight {rows}\nwidth {cols}\nmap\n{grid}\n")


def read_scen(path: str | Path) -> list[ScenarioEntry]:
    """All entries of a ``.scen`` file, in file order."""
    path = Path(path)
    out: list[ScenarioEntry] = []
    for lineno, raw in enumerate(_lines(path), start=1):
        line = raw.strip()
        if not line or (lineno == 1 and line.lower().startswith("version")):
            continue
        fields = raw.split("\t") if "\t" in raw else raw.split()
        if len(fields) != 9:
            raise FormatError(
                f"{path}:{lineno}: expected 9 tab-separated fields, got {len(fields)}"
            )
        try:
            bucket, width, height, sx, sy, gx, gy = (int(fields[k]) for k in (0, 2, 3, 4, 5, 6, 7))
            optimal = float(fields[8])
        except ValueError as err:
            raise FormatError(f"{path}:{lineno}: {err}") from err
        out.append(
            ScenarioEntry(bucket, fields[1].strip(), width, height, (sy, sx), (gy, gx), optimal)
        )
    return out


def load_instance(
    map_path: str | Path, scen_path: str | Path, k: int | None = None
) -> MapfInstance:
    """The instance made of the first ``k`` agents (all when None) of a scenario on a map."""
    free = read_map(map_path)
    entries = read_scen(scen_path)
    if k is not None:
        if not 0 < k <= len(entries):
            raise FormatError(f"{scen_path}: asked for {k} agents, the file has {len(entries)}")
        entries = entries[:k]
    rows, cols = free.shape
    for lineno, e in enumerate(entries, start=1):
        if (e.height, e.width) != (rows, cols):
            raise FormatError(
                f"{scen_path}: entry {lineno} is for a {e.width}x{e.height} map, "
                f"{map_path} is {cols}x{rows}"
            )
    names = tuple(f"agent{i}" for i in range(len(entries)))
    return MapfInstance(
        free, tuple(e.start for e in entries), tuple(e.goal for e in entries), names
    )


def octile_distance(a: tuple[int, int], b: tuple[int, int]) -> float:
    dr, dc = abs(a[0] - b[0]), abs(a[1] - b[1])
    return max(dr, dc) + (math.sqrt(2) - 1) * min(dr, dc)


def write_scen(path: str | Path, map_name: str, instance: MapfInstance) -> None:
    """Write the instance's agents in order (bucket = index // 10, as in the MovingAI suite)."""
    rows, cols = instance.shape
    lines = ["version 1"]
    for i, (s, g) in enumerate(zip(instance.starts, instance.goals, strict=True)):
        lines.append(
            f"{i // 10}\t{map_name}\t{cols}\t{rows}\t{s[1]}\t{s[0]}\t{g[1]}\t{g[0]}\t"
            f"{octile_distance(s, g):.8f}"
        )
    Path(path).write_text("\n".join(lines) + "\n")
