"""The SLAM map as a snapshot (log-odds raster in the map frame) and its changed tiles.

``SlamMap`` converts to the shared ``planners.grid.GridMap`` and to ROS ``OccupancyGrid`` values
(int8: −1 unknown, 0..100 occupancy percent). ``PatchTracker`` remembers what was last published
and yields the tiles that changed, so an agent can publish map patches at a low rate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planners.map_merge import LogOddsMap


@dataclass(frozen=True, eq=False)
class SlamMap(LogOddsMap):
    """A robot's SLAM map: log-odds (rows, cols) in its map frame, as
    ``planners.map_merge.LogOddsMap`` (the coordinator merges these), plus its ROS values."""

    def to_ros(self) -> np.ndarray:
        """int8 OccupancyGrid data: −1 where never observed, else round(100·p)."""
        out = np.rint(100.0 * self.probabilities()).astype(np.int8)
        out[self.log_odds == 0] = -1
        return out


@dataclass(frozen=True, eq=False)
class MapPatch:
    """A block of ROS int8 cells whose lower-left cell is (row, col) of the map grid."""

    row: int
    col: int
    data: np.ndarray


@dataclass(frozen=True, eq=False)
class MapUpdate:
    """Changed tiles since the last update. ``full`` means the grid geometry (shape, origin)
    changed or this is the first update: the receiver must drop its copy before applying."""

    full: bool
    shape: tuple[int, int]
    resolution: float
    origin: tuple[float, float]
    patches: tuple[MapPatch, ...]


class PatchTracker:
    """Diff successive ``SlamMap`` snapshots tile by tile against what was last handed out.

    A tile is re-sent when any of its cells moved by more than ``tolerance`` percent or changed
    between known and unknown. ``SlamMap`` shapes are multiples of the tile size (``Slam`` snaps
    its bounds to ``SlamParams.map_tile``)."""

    def __init__(self, tile: int, tolerance: int) -> None:
        self.tile = tile
        self.tolerance = tolerance
        self._sent: np.ndarray | None = None
        self._geometry: tuple | None = None

    def update(self, current: SlamMap) -> MapUpdate:
        fresh = current.to_ros()
        geometry = (current.shape, current.resolution, current.origin)
        t = self.tile
        rows, cols = current.shape
        if rows % t or cols % t:
            raise ValueError(f"map shape {current.shape} is not a multiple of the tile size {t}")
        full = self._sent is None or geometry != self._geometry
        if full:
            changed = fresh != -1
            self._sent = np.full_like(fresh, -1)
        else:
            old = self._sent
            changed = ((old == -1) != (fresh == -1)) | (
                np.abs(fresh.astype(np.int16) - old.astype(np.int16)) > self.tolerance
            )
        tiles = changed.reshape(rows // t, t, cols // t, t).any(axis=(1, 3))
        patches = []
        for tr, tc in np.argwhere(tiles):
            r, c = int(tr) * t, int(tc) * t
            block = fresh[r : r + t, c : c + t].copy()
            self._sent[r : r + t, c : c + t] = block
            patches.append(MapPatch(r, c, block))
        self._geometry = geometry
        return MapUpdate(full, current.shape, current.resolution, current.origin, tuple(patches))
