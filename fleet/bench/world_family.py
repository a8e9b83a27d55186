"""A family of generated stress worlds for deconfliction: two or three rooms in a row joined by
straight corridors of a given width and length, a plain doorway, or an L-shaped corridor, with
a little furniture in the rooms and robots starting at both ends, so traffic goes through the
passages both ways.

Each member is a frozen :class:`FamilyMember`; :func:`layout` turns it into walls (centre lines
of walls ``WALL_T`` thick, as a world YAML gives them), furniture, a dock and starts, and
:func:`write_world` writes the world YAML that ``fleet.world.load_world`` reads. Everything is
deterministic from the member's parameters. A passage's width is measured between the walls'
faces; a straight corridor's length between the centre lines of the two rooms' walls it joins.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path
from typing import Any, Literal

import yaml

Point = tuple[float, float]
Segment = tuple[float, float, float, float]
Shape = Literal["straight", "door", "ell"]

WALL_T = 0.1
ROOM_W, ROOM_H = 3.4, 3.0
# the first start's and the furniture's place in a room, from its walls' centre lines (m)
START_IN, START_STEP, START_UP = 0.9, 1.0, 0.7
TABLE_SIZE = (0.8, 0.5)
TABLE_AT = (0.36, 0.72)  # fractions of the room's width and height
GRID_M = 0.05  # the lattice the passages' faces are put on (the planners' fine grid)
# the L: its first leg leaves the first room's right wall and turns up into the second room,
# whose left wall stands this far right of the first room's, the turn this far inside it
ELL_ROOM_GAP, ELL_TURN_IN = 0.6, 1.0


@dataclass(frozen=True)
class FamilyMember:
    """One generated world: ``rooms`` rooms in a row joined by passages ``width`` m wide (face
    to face) and ``length`` m long; ``shape`` straight (a corridor), door (a gap in the wall
    between two rooms, no corridor) or ell (an L-shaped corridor, two rooms)."""

    shape: Shape
    width: float
    length: float = 0.0
    rooms: int = 2

    @property
    def name(self) -> str:
        """The member's name, from its parameters: c0.45x2.5, door0.8, L0.6, 3rooms0.6."""
        if self.shape == "door":
            return f"door{self.width:g}"
        if self.shape == "ell":
            return f"L{self.width:g}"
        if self.rooms != 2:
            return f"{self.rooms}rooms{self.width:g}"
        return f"c{self.width:g}x{self.length:g}"


FAMILY = (
    FamilyMember("straight", 0.45, 2.5),
    FamilyMember("straight", 0.6, 1.0),
    FamilyMember("straight", 0.6, 4.0),
    FamilyMember("straight", 0.75, 2.5),
    FamilyMember("straight", 0.9, 2.5),
    FamilyMember("door", 0.8),
    FamilyMember("ell", 0.6),
    FamilyMember("straight", 0.6, 2.5, rooms=3),
)


@dataclass(frozen=True)
class Gauge:
    """Where a passage's width can be measured: a point in its middle and the axis across it
    (``x`` or ``y``)."""

    point: Point
    across: Literal["x", "y"]
    width: float


@dataclass(frozen=True)
class Layout:
    """A member's floor plan: wall centre lines, furniture boxes (centre, size), the dock,
    starts (x, y, heading), one free point per room and a gauge per passage."""

    name: str
    walls: tuple[Segment, ...]
    furniture: tuple[tuple[Point, tuple[float, float]], ...]
    dock: tuple[float, float, float]
    starts: tuple[tuple[float, float, float], ...]
    room_points: tuple[Point, ...]
    gauges: tuple[Gauge, ...]


def _on_lattice(width: float) -> float:
    """The passage's centre line near the rooms' middle height, so that both its faces lie on
    the ``GRID_M`` lattice of a grid whose origin is the outer face of the floor's wall."""
    half = width / 2
    low = round((ROOM_H / 2 - half + WALL_T / 2) / GRID_M) * GRID_M - WALL_T / 2
    return round(low + half, 4)


def _segments(points: list[Point]) -> tuple[Segment, ...]:
    """The walls along a closed outline, zero-length pieces left out."""
    pairs = zip(points, points[1:] + points[:1], strict=True)
    return tuple(
        (round(a[0], 4), round(a[1], 4), round(b[0], 4), round(b[1], 4))
        for a, b in pairs
        if math.hypot(b[0] - a[0], b[1] - a[1]) > 1e-9
    )


def _row_outline(xs: list[tuple[float, float]], yc: float, half_gap: float) -> list[Point]:
    """The outline of rooms ``xs`` (left and right wall x) in a row, ``ROOM_H`` high, each
    joined to the next by a passage centred at ``yc`` whose walls are ``half_gap`` from it."""
    low, high = yc - half_gap, yc + half_gap
    out: list[Point] = [(xs[0][0], 0.0)]
    for (_, x1), (nx0, _) in pairwise(xs):
        out += [(x1, 0.0), (x1, low), (nx0, low), (nx0, 0.0)]
    out += [(xs[-1][1], 0.0), (xs[-1][1], ROOM_H)]
    for (_, px1), (x0, _) in reversed(list(pairwise(xs))):
        out += [(x0, ROOM_H), (x0, high), (px1, high), (px1, ROOM_H)]
    out.append((xs[0][0], ROOM_H))
    return out


def _ell_outline(yc: float, half_gap: float) -> tuple[list[Point], tuple[float, float, float]]:
    """The L: the first room, its corridor out of the right wall at ``yc`` turning up into the
    second room above and to the right. Also the second room's left x, right x and floor y."""
    bx0 = ROOM_W + ELL_ROOM_GAP
    bx1, by0 = bx0 + ROOM_W, ROOM_H
    turn = bx0 + ELL_TURN_IN
    outline = [
        (0.0, 0.0),
        (ROOM_W, 0.0),
        (ROOM_W, yc - half_gap),
        (turn + half_gap, yc - half_gap),
        (turn + half_gap, by0),
        (bx1, by0),
        (bx1, by0 + ROOM_H),
        (bx0, by0 + ROOM_H),
        (bx0, by0),
        (turn - half_gap, by0),
        (turn - half_gap, yc + half_gap),
        (ROOM_W, yc + half_gap),
        (ROOM_W, ROOM_H),
        (0.0, ROOM_H),
    ]
    return outline, (bx0, bx1, by0)


def _room_contents(
    x0: float, x1: float, y0: float, first: bool, last: bool
) -> tuple[tuple[Point, tuple[float, float]], list[tuple[float, float, float]], Point]:
    """A room's table, its starts (two in the first and in the last room, facing the other
    rooms) and a free point in it."""
    table = ((x0 + TABLE_AT[0] * (x1 - x0), y0 + TABLE_AT[1] * ROOM_H), TABLE_SIZE)
    y = y0 + START_UP
    starts = []
    if first:
        starts = [(x0 + START_IN, y, 0.0), (x0 + START_IN + START_STEP, y, 0.0)]
    elif last:
        starts = [(x1 - START_IN, y, math.pi), (x1 - START_IN - START_STEP, y, math.pi)]
    return table, starts, ((x0 + x1) / 2, y)


def layout(member: FamilyMember) -> Layout:
    """The member's floor plan (see the module's docstring)."""
    yc = _on_lattice(member.width)
    half_gap = (member.width + WALL_T) / 2
    if member.shape == "ell":
        outline, (bx0, bx1, by0) = _ell_outline(yc, half_gap)
        rooms = [(0.0, ROOM_W, 0.0), (bx0, bx1, by0)]
        turn = bx0 + ELL_TURN_IN
        gauges = (
            Gauge(((ROOM_W + turn) / 2, yc), "y", member.width),
            Gauge((turn, (yc + by0) / 2), "x", member.width),
        )
    else:
        length = 0.0 if member.shape == "door" else member.length
        xs = [(i * (ROOM_W + length), i * (ROOM_W + length) + ROOM_W) for i in range(member.rooms)]
        outline = _row_outline(xs, yc, half_gap)
        rooms = [(x0, x1, 0.0) for x0, x1 in xs]
        gauges = tuple(
            Gauge(((x1 + nx0) / 2, yc), "y", member.width) for (_, x1), (nx0, _) in pairwise(xs)
        )
    furniture, starts, points = [], [], []
    for i, (x0, x1, y0) in enumerate(rooms):
        table, mine, point = _room_contents(x0, x1, y0, i == 0, i == len(rooms) - 1)
        furniture.append(table)
        starts += mine
        points.append(point)
    return Layout(
        member.name,
        _segments(outline),
        tuple(furniture),
        (0.45, yc, 0.0),
        tuple((round(x, 4), round(y, 4), round(h, 5)) for x, y, h in starts),
        tuple(points),
        gauges,
    )


def world_yaml(plan: Layout) -> dict[str, Any]:
    """The world YAML's fields for a layout."""
    return {
        "name": plan.name,
        "description": "generated by fleet.bench.world_family",
        "wall_thickness": WALL_T,
        "walls": [list(w) for w in plan.walls],
        "furniture": [
            {"name": f"table{i}", "type": "box", "center": list(c), "size": list(s)}
            for i, (c, s) in enumerate(plan.furniture)
        ],
        "dock": list(plan.dock),
        "starts": [list(s) for s in plan.starts],
    }


def write_world(member: FamilyMember, directory: Path) -> Path:
    """Write the member's world YAML as ``directory / <name>.yaml``; its path."""
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{member.name}.yaml"
    text = yaml.safe_dump(world_yaml(layout(member)), sort_keys=False, default_flow_style=None)
    path.write_text(text)
    return path


def members(names: str) -> list[FamilyMember]:
    """The family's members named in a comma-separated list (all of them for "" or "all");
    raises ValueError naming an unknown one."""
    chosen = [n.strip() for n in names.split(",") if n.strip() and n.strip() != "all"]
    by_name = {m.name: m for m in FAMILY}
    unknown = [n for n in chosen if n not in by_name]
    if unknown:
        raise ValueError(f"{', '.join(unknown)}: choose from {', '.join(by_name)}")
    return [by_name[n] for n in chosen] if chosen else list(FAMILY)
