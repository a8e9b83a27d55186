"""Grids on the bus as :class:`~fleet.protocol.MapPatches`: the floor plan, and robots' maps.

The coordinator serves the floor plan it cuts tasks from on ``coord/map``; robots price travel
on it (walls they have not seen yet included) for their bids. Cells travel as ROS
OccupancyGrid values: 100 occupied, 0 free, −1 unknown; the grid is padded to whole tiles with
unknown cells. A robot's SLAM map travels as its changed tiles; :func:`apply_patches` keeps a
receiver's copy of it.
"""

from __future__ import annotations

import numpy as np

from fleet.protocol import MapPatches
from planners.grid import GridMap

TILE = 32


def pack_grid(grid: GridMap, stamp: float = 0.0) -> MapPatches:
    rows, cols = grid.shape
    padded = np.full((-(-rows // TILE) * TILE, -(-cols // TILE) * TILE), -1, dtype=np.int8)
    padded[:rows, :cols] = np.where(grid.occupied, 100, np.where(grid.unknown, -1, 0))
    blocks = [
        (r, c, padded[r : r + TILE, c : c + TILE])
        for r in range(0, padded.shape[0], TILE)
        for c in range(0, padded.shape[1], TILE)
    ]
    return MapPatches.pack(stamp, 1, True, padded.shape, grid.resolution, grid.origin, TILE, blocks)


def unpack_grid(msg: MapPatches) -> GridMap:
    """The grid a full ``MapPatches`` holds (tiles it does not hold are unknown)."""
    cells = np.full((msg.rows, msg.cols), -1, dtype=np.int8)
    t = msg.tile
    for r, c, block in zip(msg.patch_rows, msg.patch_cols, msg.blocks, strict=True):
        cells[r : r + t, c : c + t] = block
    return GridMap(cells >= 50, cells < 0, msg.resolution, (msg.origin_x, msg.origin_y))


def apply_patches(cells: np.ndarray | None, msg: MapPatches) -> np.ndarray:
    """A receiver's copy of a robot's map (int8 OccupancyGrid values, ``msg.rows`` ×
    ``msg.cols``) with ``msg``'s tiles written in: a new all-unknown copy first when ``msg`` is
    ``full`` or the copy is another shape (ValueError: a patch that is not full cannot start a
    copy)."""
    shape = (msg.rows, msg.cols)
    if msg.full or cells is None or cells.shape != shape:
        if not msg.full:
            raise ValueError("changed tiles of a map whose whole was never received")
        cells = np.full(shape, -1, dtype=np.int8)
    else:
        cells = cells.copy()
    t = msg.tile
    for r, c, block in zip(msg.patch_rows, msg.patch_cols, msg.blocks, strict=True):
        dst = cells[r : r + t, c : c + t]
        dst[...] = block[: dst.shape[0], : dst.shape[1]]
    return cells
