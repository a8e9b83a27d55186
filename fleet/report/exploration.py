"""An exploration run judged: the fleet's merged map against the true floor, and what it took.

Scoring only: the truth (the world file's floor) is read here, after the run, never by the
exploring processes. The true floor is the world's free cells 4-connected to a robot's start (closed
spaces no robot can enter are not floor); the merged map's free space is compared with it cell
by cell on the truth's grid (each true cell looks up the merged cell holding its centre;
outside the merged map is not free): free-space IoU = |mapped ∩ true| / |mapped ∪ true|. The
walls: the true wall cells are the world's occupied cells 8-adjacent to that floor (the faces a
robot's lidar can see); a true wall cell is found when a mapped occupied cell's centre lies
within ``WALL_TOLERANCE_M`` of its centre. What a cleaning plan on the map loses against one on
the world file, by cause (:func:`plan_floor_lost`), and how the map grew over the run, from the
coordinator's ``explored`` events (:func:`growth`).
"""

from __future__ import annotations

import math
import re
import sqlite3
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image
from scipy import ndimage
from scipy.spatial import cKDTree

from fleet.world import World
from planners.grid import GridMap, cleanable, clearance, reachable

EXPLORE_REPORT = "explore.json"
MAP_PNG = "map.png"
# map.png shows each map cell as this many pixels a side
PNG_SCALE = 4
# a true wall is found when a mapped wall lies this close (issue 27's target: 95 % within 5 cm)
WALL_TOLERANCE_M = 0.05


def true_floor(
    world: World, resolution: float, start: tuple[float, float]
) -> tuple[GridMap, np.ndarray]:
    """The world's grid at ``resolution`` and its floor: free cells 4-connected to ``start``
    (a robot's start)."""
    grid = world.grid(resolution)
    return grid, reachable(grid.free, grid.world_to_cell(np.array([start], dtype=float)))


def mapped_free_on(mapped: GridMap, truth: GridMap) -> np.ndarray:
    """``mapped``'s free cells on ``truth``'s grid: each truth cell takes the mapped cell
    holding its centre (outside ``mapped``: not free)."""
    return mapped_on(mapped, truth).free


def mapped_on(mapped: GridMap, truth: GridMap) -> GridMap:
    """``mapped`` on ``truth``'s grid: each truth cell takes the state of the mapped cell
    holding its centre (outside ``mapped``: unknown)."""
    rows, cols = np.indices(truth.shape)
    centres = truth.cell_to_world(np.stack([rows.ravel(), cols.ravel()], axis=-1))
    rc = mapped.world_to_cell(centres)
    inside = mapped.in_bounds(rc)
    occupied = np.zeros(len(rc), dtype=bool)
    occupied[inside] = mapped.occupied[rc[inside, 0], rc[inside, 1]]
    unknown = ~inside
    unknown[inside] = mapped.unknown[rc[inside, 0], rc[inside, 1]]
    shape = truth.shape
    return GridMap(occupied.reshape(shape), unknown.reshape(shape), truth.resolution, truth.origin)


def plan_floor_lost(
    mapped: GridMap,
    world: World,
    start: tuple[float, float],
    centre_clearance: float,
    half_width: float,
    resolution: float = 0.025,
) -> dict[str, float]:
    """The floor a plan on ``mapped`` puts out of the brush's reach that a plan on the world
    file reaches, by cause (m², on the truth's grid at ``resolution``, the coordinator's plan
    resolution). The brush reaches the cells within ``half_width`` of a robot-centre cell:
    ``centre_clearance`` from every occupied or unknown cell, 4-connected to ``start``
    (``planners.grid.cleanable``). ``walls_on_floor_m2``: what clearing the mapped occupied
    cells that lie on true floor would give back (walls and furniture drawn into the floor:
    a map cell that a face crosses is occupied whole); ``unknown_on_floor_m2``: what clearing the
    unknown cells on true floor would give back (corners no scan reached); ``both_m2`` what
    clearing both gives back (more than the two summed where one cause hides the other)."""
    truth = world.grid(resolution)
    on = mapped_on(mapped, truth)
    at = truth.world_to_cell(np.array([start], dtype=float))

    def reached(occupied: np.ndarray, unknown: np.ndarray) -> np.ndarray:
        g = GridMap(occupied, unknown, truth.resolution, truth.origin)
        return cleanable(g, reachable(clearance(g) >= centre_clearance, at), half_width)

    floor = truth.free
    true_reach = reached(truth.occupied, truth.unknown)
    lost = true_reach & ~reached(on.occupied, on.unknown)
    walls = true_reach & ~reached(on.occupied & ~floor, on.unknown)
    corners = true_reach & ~reached(on.occupied, on.unknown & ~floor)
    both = true_reach & ~reached(on.occupied & ~floor, on.unknown & ~floor)
    cell = truth.resolution**2
    return {
        "brushable_m2": round(float(true_reach.sum()) * cell, 3),
        "lost_m2": round(float(lost.sum()) * cell, 3),
        "walls_on_floor_m2": round(float(lost.sum() - walls.sum()) * cell, 3),
        "unknown_on_floor_m2": round(float(lost.sum() - corners.sum()) * cell, 3),
        "both_m2": round(float(lost.sum() - both.sum()) * cell, 3),
    }


def free_iou(mapped: GridMap, truth: GridMap, floor: np.ndarray) -> float:
    """Free-space IoU of ``mapped`` against ``floor`` (a mask on ``truth``'s grid)."""
    free = mapped_free_on(mapped, truth)
    union = int((free | floor).sum())
    return float((free & floor).sum()) / union if union else 0.0


def walls_within(
    mapped: GridMap, truth: GridMap, floor: np.ndarray, tolerance: float = WALL_TOLERANCE_M
) -> float:
    """The share of the true walls facing ``floor`` (occupied cells of ``truth`` 8-adjacent to
    it) with a mapped occupied cell's centre within ``tolerance`` (m) of theirs; 0 with no
    mapped wall."""
    faces = truth.occupied & ndimage.binary_dilation(floor, structure=np.ones((3, 3), bool))
    walls = truth.cell_to_world(np.argwhere(faces))
    found = mapped.cell_to_world(np.argwhere(mapped.occupied))
    if not len(walls) or not len(found):
        return 0.0
    # a hair over the tolerance: cell centres a whole number of cells apart are exactly it
    dist, _ = cKDTree(found).query(walls, distance_upper_bound=tolerance + 1e-6)
    return float(np.isfinite(dist).mean())


def path_lengths(tracks: Mapping[str, Sequence[Sequence[float]] | np.ndarray]) -> dict[str, float]:
    """Metres each robot drove along its track of (sim s, x, y)."""
    out = {}
    for rid, track in sorted(tracks.items()):
        xy = np.array([(x, y) for _, x, y in track], dtype=float).reshape(-1, 2)
        out[rid] = round(float(np.hypot(*np.diff(xy, axis=0).T).sum()), 2) if len(xy) else 0.0
    return out


def write_map_png(pgm: Path, png: Path) -> None:
    """The map_server image ``pgm`` as a PNG, each cell ``PNG_SCALE`` pixels a side."""
    with Image.open(pgm) as im:
        im.resize((im.width * PNG_SCALE, im.height * PNG_SCALE), Image.Resampling.NEAREST).save(png)


def frontier_counts(state: Path) -> dict[str, int]:
    """From the coordinator's SQLite ``state`` (read-only): ``assigned``, the frontier tasks
    awarded to a robot (each once), and the frontier tasks by their final state."""
    db = sqlite3.connect(f"file:{state}?mode=ro", uri=True)
    try:
        (assigned,) = db.execute(
            "SELECT COUNT(DISTINCT task) FROM events WHERE kind = 'awarded'"
        ).fetchone()
        states = db.execute("SELECT state, COUNT(*) FROM tasks GROUP BY state").fetchall()
    finally:
        db.close()
    return {"assigned": int(assigned), **{str(s): int(n) for s, n in states}}


# an `explored` event's detail begins "known 41.5 m², 5 frontiers, ..."
EXPLORED = re.compile(r"known ([\d.]+) m², (\d+) frontiers")


def growth(state: Path) -> list[list[float]]:
    """From the coordinator's SQLite ``state`` (read-only), the merged map as it grew: one
    [sim s, known m², frontiers] per update that changed either (its ``explored`` events)."""
    db = sqlite3.connect(f"file:{state}?mode=ro", uri=True)
    try:
        rows = db.execute(
            "SELECT sim, detail FROM events WHERE kind = 'explored' ORDER BY seq"
        ).fetchall()
    finally:
        db.close()
    out: list[list[float]] = []
    for sim, detail in rows:
        m = EXPLORED.match(detail)
        if m is None:
            continue
        point = [round(float(sim), 1), float(m.group(1)), int(m.group(2))]
        if not out or point[1:] != out[-1][1:]:
            out.append(point)
    return out


# a `placed` event's detail begins "its map matched at (1.23, -0.45, 90.0°)"
PLACED = re.compile(r"its map matched at \((-?[\d.]+), (-?[\d.]+), (-?[\d.]+)°\)")


def placements(
    state: Path, starts: dict[str, tuple[float, float, float]]
) -> dict[str, dict[str, Any]]:
    """From the coordinator's SQLite ``state`` (read-only), how each robot of ``starts`` (those
    that started with no known pose, each with its true start pose) was placed: the sim time
    of its ``placed`` event (None if never), the placement's error against the truth (its own
    frame's origin is where it started), and how many ``unplaced`` events came first."""
    db = sqlite3.connect(f"file:{state}?mode=ro", uri=True)
    try:
        rows = db.execute(
            "SELECT sim, kind, robot, detail FROM events WHERE kind IN ('placed', 'unplaced') "
            "ORDER BY seq"
        ).fetchall()
    finally:
        db.close()
    out: dict[str, dict[str, Any]] = {
        rid: {"placed_s": None, "error_m": None, "error_deg": None, "refused": 0}
        for rid in sorted(starts)
    }
    for sim, kind, rid, detail in rows:
        entry = out.get(rid)
        if entry is None or entry["placed_s"] is not None:
            continue
        if kind == "unplaced":
            entry["refused"] += 1
            continue
        m = PLACED.match(detail)
        if m is None:
            continue
        x, y, deg = (float(v) for v in m.groups())
        sx, sy, sth = starts[rid]
        turn = math.degrees(
            math.atan2(math.sin(math.radians(deg) - sth), math.cos(math.radians(deg) - sth))
        )
        entry.update(
            placed_s=round(float(sim), 1),
            error_m=round(math.hypot(x - sx, y - sy), 3),
            error_deg=round(abs(turn), 1),
        )
    return out
