"""Where the floor the robots see differs from the stored map they clean on: furniture moved.

Once the stored map is accepted (``planners.map_check``), a piece of furniture moved since the
map was made shows as cells the robots' fused SLAM map holds with confidence against the stored
map: occupied where the stored map has floor (furniture moved in), free where it has an obstacle
(furniture taken away). :func:`find_changes` finds them cell by cell on the fused log-odds (the
occupancy grid's evidence, Thrun, Burgard and Fox 2005, §9.2; a cell counts once its probability
is at least ``confidence``, or at most 1 − ``confidence`` for free, which one hit or one miss of
a single scan never reaches) and groups them into blobs (8-connected, cells a cell apart
joined). What SLAM's own error explains is left out:

- walls a cell or two off the stored map's: an occupied cell counts only ``wall_margin_m`` or
  more from the stored map's obstacles and unknown cells, and a free cell only ``wall_margin_m``
  or more from every cell the robots saw occupied at all;
- a robot's body (a peer the scan's cut-out missed): an occupied blob whose cells all lie
  within ``robot_clear_m`` of a robot's centre (a face a robot stands beside reaches beyond);
- specks and slivers: an added blob whose extent (the longer side of its bounding box) is
  under ``min_size_m``, a freed one whose shorter side is (the stored map's wall cells that a
  face only halves are seen free along it);
- floor the stored map never knew (corners exploring did not reach): a freed blob counts only if
  it holds a cell the stored map marks occupied.

An added blob is what the scans saw of the furniture: its faces towards the robots, not its
inside; :func:`obstacle_cells` takes the box they span, joined with what was found of the same
piece before.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from planners.grid import GridMap, clearance
from planners.map_merge import LogOddsMap

ADDED = "added"
REMOVED = "removed"


@dataclass(frozen=True)
class MapChangeParams:
    """What counts as a change (see the module docstring)."""

    confidence: float = 0.85
    min_size_m: float = 0.2
    wall_margin_m: float = 0.15
    robot_clear_m: float = 0.25

    def validate(self) -> None:
        if not 0.5 < self.confidence < 1.0:
            raise ValueError(f"confidence must be within (0.5, 1), got {self.confidence}")
        for name in ("min_size_m", "wall_margin_m", "robot_clear_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0")


@dataclass(frozen=True, eq=False)
class MapChange:
    """One blob: :data:`ADDED` (seen occupied on the stored map's floor) or :data:`REMOVED`
    (seen free where the stored map has an obstacle); ``cells`` (K, 2) the world centres of its
    cells, squares of ``cell_size`` metres."""

    kind: str
    cells: np.ndarray
    cell_size: float

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of its cells' edges, world metres."""
        lo = self.cells.min(axis=0) - self.cell_size / 2
        hi = self.cells.max(axis=0) + self.cell_size / 2
        return (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))

    @property
    def centre(self) -> tuple[float, float]:
        x0, y0, x1, y1 = self.bounds
        return ((x0 + x1) / 2, (y0 + y1) / 2)

    @property
    def size_m(self) -> float:
        """The longer side of its bounding box."""
        x0, y0, x1, y1 = self.bounds
        return max(x1 - x0, y1 - y0)

    def describe(self) -> str:
        """In words, world metres."""
        x0, y0, x1, y1 = self.bounds
        what = (
            "an obstacle the stored map does not have"
            if self.kind == ADDED
            else ("floor where the stored map has an obstacle")
        )
        return (
            f"{what}: {x1 - x0:.2f} × {y1 - y0:.2f} m at ({self.centre[0]:.2f}, "
            f"{self.centre[1]:.2f}), x {x0:.2f}–{x1:.2f}, y {y0:.2f}–{y1:.2f} "
            f"({len(self.cells)} cells seen {'occupied' if self.kind == ADDED else 'free'})"
        )


def find_changes(
    seen: LogOddsMap,
    stored: GridMap,
    params: MapChangeParams,
    robots_xy: np.ndarray | None = None,
    stored_clearance: np.ndarray | None = None,
) -> tuple[MapChange, ...]:
    """The blobs where ``seen`` (the robots' fused map, in the stored map's frame) differs from
    ``stored``, robots at ``robots_xy`` ((R, 2) world metres); added ones first.
    ``stored_clearance`` is ``planners.grid.clearance(stored)`` when the caller keeps it (a
    watch that looks again and again at one stored map), or the clearance of the map as it was
    stored, before the furniture found since went on it: then a face seen near a piece found
    before (its far side, seen later from the other side) is a change, however near, but a
    cell on the piece is not."""
    params.validate()
    level = math.log(params.confidence / (1.0 - params.confidence))
    rows, cols = seen.shape
    xy = seen.cell_to_world(np.stack(np.mgrid[0:rows, 0:cols], axis=-1))
    at = stored.world_to_cell(xy)
    inside = stored.in_bounds(at)
    r, c = np.where(inside, at[..., 0], 0), np.where(inside, at[..., 1], 0)
    room_of = clearance(stored) if stored_clearance is None else stored_clearance
    room = np.where(inside, room_of[r, c], 0.0)
    stored_occupied = inside & stored.occupied[r, c]
    added = (seen.log_odds >= level) & (room >= params.wall_margin_m) & ~stored_occupied
    body = np.zeros(seen.shape, dtype=bool)
    for p in np.asarray(robots_xy if robots_xy is not None else (), float).reshape(-1, 2):
        body |= np.hypot(xy[..., 0] - p[0], xy[..., 1] - p[1]) <= params.robot_clear_m
    seen_walls = ndimage.distance_transform_edt(seen.log_odds <= 0) * seen.resolution
    freed = (seen.log_odds <= -level) & inside & ~stored.free[r, c]
    freed &= seen_walls >= params.wall_margin_m
    out = [
        MapChange(ADDED, xy[blob], seen.resolution)
        for blob in _blobs(added)
        if not body[blob].all()
    ] + [
        MapChange(REMOVED, xy[blob], seen.resolution)
        for blob in _blobs(freed)
        if stored_occupied[blob].any()
    ]
    return tuple(ch for ch in out if _big_enough(ch, params.min_size_m))


def _big_enough(change: MapChange, min_size_m: float) -> bool:
    """An added blob's longer side, a freed blob's shorter side at least ``min_size_m``: the
    faces of furniture moved in are thin, the floor it leaves is not (a freed sliver is a stored
    wall cell that a face only halves)."""
    x0, y0, x1, y1 = change.bounds
    sides = (x1 - x0, y1 - y0)
    return (max(sides) if change.kind == ADDED else min(sides)) >= min_size_m - 1e-9


def _blobs(mask: np.ndarray) -> list[np.ndarray]:
    """``mask``'s cells grouped: 8-connected, cells one cell apart joined (boolean masks)."""
    if not mask.any():
        return []
    joined = ndimage.binary_dilation(mask, structure=np.ones((3, 3), bool))
    labels, n = ndimage.label(joined, structure=np.ones((3, 3), bool))
    return [b for i in range(1, n + 1) if (b := mask & (labels == i)).any()]


def obstacle_cells(
    change: MapChange, earlier: Sequence[np.ndarray] = (), join_m: float = 0.0
) -> tuple[np.ndarray, list[int]]:
    """An added blob as an obstacle: every cell of the box its cells span, joined with the
    obstacles of ``earlier`` changes ((K, 2) world centres each) that come within ``join_m`` of
    it; (the box's cell centres on the blob's own lattice, the indices of ``earlier`` joined).

    Scans see furniture's faces towards the robots, not its inside nor its far faces: two faces
    seen at a corner span the whole of a box, one face only itself, and a face seen later from
    another side (a change of its own: cells seen occupied off what was put on the map before,
    see :func:`find_changes`) spans the whole piece once joined with it. Nothing passes between
    pieces ``join_m`` apart, so filling the gap between them costs no floor a robot reaches."""
    cells = np.asarray(change.cells, float).reshape(-1, 2)
    joined = []
    for i, other in enumerate(earlier):
        gaps = np.hypot(*(cells[:, None, :] - np.asarray(other)[None, :, :]).transpose(2, 0, 1))
        if gaps.min() <= join_m + 1e-9:
            joined.append(i)
    every = np.vstack([cells, *(np.asarray(earlier[i]) for i in joined)])
    res = change.cell_size
    lo = every.min(axis=0)
    n = np.rint((every.max(axis=0) - lo) / res).astype(int) + 1
    cols, rows = np.meshgrid(np.arange(n[0]), np.arange(n[1]))
    return lo + np.stack([cols.ravel(), rows.ravel()], axis=-1) * res, joined


def with_cells(grid: GridMap, cells: np.ndarray, cell_size: float, occupied: bool) -> GridMap:
    """``grid`` with every cell whose centre falls in one of the squares of ``cell_size``
    centred at ``cells`` ((K, 2) world metres) set occupied (``occupied``) or free."""
    occ, unknown = grid.occupied.copy(), grid.unknown.copy()
    cells = np.asarray(cells, float).reshape(-1, 2)
    if len(cells):
        n = max(1, math.ceil(cell_size / grid.resolution))
        offsets = ((np.arange(n) + 0.5) / n - 0.5) * cell_size
        dx, dy = np.meshgrid(offsets, offsets)
        pts = (cells[:, None, :] + np.stack([dx.ravel(), dy.ravel()], axis=-1)[None]).reshape(-1, 2)
        rc = grid.world_to_cell(pts)
        rc = rc[grid.in_bounds(rc)]
        occ[rc[:, 0], rc[:, 1]] = occupied
        unknown[rc[:, 0], rc[:, 1]] = False
    return GridMap(occ, unknown, grid.resolution, grid.origin)
