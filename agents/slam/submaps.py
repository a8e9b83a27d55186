"""The SLAM's submaps (Hess et al. 2016): small occupancy grids, each anchored at a pose of the
pose graph, and the map composed from them.

Each node is inserted into the two active submaps (each receives ``submap_nodes`` nodes; a new
one starts every ``submap_nodes/2`` nodes, or once the robot is ``submap_travel/2`` from where
the newest one started), so the older one, which tracking matches against, is always well
filled. When a third starts, the oldest is finished: cropped to what it observed, with its
likelihood field built once for loop-closure searches.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from agents.slam.geometry import relative, transform_points
from agents.slam.matcher import LikelihoodField
from agents.slam.occupancy import LogOddsGrid, log_odds
from agents.slam.pose_graph import PoseGraph
from agents.slam.slam_map import SlamMap
from fleet.slam_params import SlamParams


def wall_lattice(points: np.ndarray, resolution: float) -> np.ndarray:
    """Cell-boundary offsets (x, y), each in [0, resolution), that put the walls of a scan's
    map-frame ``points`` (N, 2) on cell centres: per axis the circular mean of the points'
    coordinates modulo the resolution (their phase on the lattice), half a cell on.

    A wall on a cell boundary is split between two cells by range noise, and a wall a quarter
    cell off a centre is drawn at the centre: matching against either settles the pose up to
    half a cell off, in the first scans, and the map and every pose after stay off by it
    (18–21 mm on a room a quarter to 1.3 cells off the lattice, 32–40 mm on the home route with
    its walls on the boundaries). Points on walls across an axis share their phase on it; those
    along it spread over every phase and cancel in the mean; walls off the axes cancel on both,
    and leave the lattice to chance, as it was.
    """
    phase = 2.0 * np.pi / resolution * np.asarray(points, dtype=float)
    mean = np.exp(1j * phase).sum(axis=0)
    centre = np.angle(mean) / (2.0 * np.pi) * resolution
    return np.mod(centre + 0.5 * resolution, resolution)


def map_lattice(origin: tuple[float, float], resolution: float) -> np.ndarray:
    """The cell-boundary offsets (x, y) of a map whose corner is ``origin``."""
    return np.mod(np.asarray(origin, dtype=float), resolution)


@dataclass(eq=False)
class Submap:
    """One submap: its place in order, the graph id of its pose, its grid, the nodes inserted,
    whether it is finished, and its likelihood field as built when it held ``field_nodes``."""

    index: int
    graph_id: int
    grid: LogOddsGrid
    nodes: int = 0
    finished: bool = False
    field: LikelihoodField | None = None
    field_nodes: int = -1


@dataclass(eq=False)
class _MapCache:
    origin: tuple[float, float]
    log_odds: np.ndarray
    submaps: set[int] = field(default_factory=set)


class Submaps:
    """Every submap kept, in order (``all``), and the two being filled (``active``, oldest
    first); ``trimmed`` counts the finished ones dropped (``drop``).

    A submap's pose is its pose in ``graph``; its grid covers ± (range_max + submap_travel)
    around it, enough for every scan inserted while it is active.
    """

    def __init__(self, params: SlamParams, graph: PoseGraph, range_max: float) -> None:
        self.params = params
        self._graph = graph
        self.all: list[Submap] = []
        self.active: list[Submap] = []
        self._cache: _MapCache | None = None
        self._started = 0
        self.trimmed = 0
        self._half_size = range_max + params.submap_travel
        # Cell boundaries of the map lie at k·resolution + lattice (per axis): by default
        # (k + ½)·resolution, so walls on round coordinates fall on cell centres; ``Slam`` puts
        # them where its first scan's walls fall on centres (:func:`wall_lattice`).
        self.lattice = np.full(2, 0.5 * params.resolution)

    def start(self, pose: np.ndarray) -> Submap | None:
        """Start a submap at ``pose``'s position, its grid axis-aligned with the map frame and
        snapped to the map's cell lattice: all submaps then quantize a wall into the same cells,
        so the discretization bias does not differ (and accumulate) between submaps, and the
        map is composed from them without resampling across lattices. Returns the submap this
        finished, if any."""
        p = self.params
        shift = self.lattice
        snapped = np.array(
            [
                round((pose[0] - shift[0]) / p.resolution) * p.resolution + shift[0],
                round((pose[1] - shift[1]) / p.resolution) * p.resolution + shift[1],
                0.0,
            ]
        )
        n = math.ceil(2 * self._half_size / p.resolution)
        grid = LogOddsGrid(
            (n, n),
            (-self._half_size, -self._half_size),
            p.resolution,
            p.p_hit,
            p.p_miss,
            p.p_min,
            p.p_max,
        )
        submap = Submap(self._started, self._graph.add_pose(snapped), grid)
        self._started += 1
        self.all.append(submap)
        self.active.append(submap)
        if len(self.active) <= 2:
            return None
        old = self.active.pop(0)
        old.finished = True
        margin = math.ceil(max(p.loop_window_xy, 3.0 * p.match_sigma) / p.resolution) + 1
        old.grid = old.grid.cropped(margin)
        old.field = LikelihoodField(old.grid, p.match_sigma)
        old.field_nodes = old.nodes
        return old

    def add_node(
        self, node_id: int, pose: np.ndarray, points: np.ndarray, misses: np.ndarray
    ) -> Submap | None:
        """Insert the node's scan ``points`` and missing rays' ends ``misses`` (sensor frame) at
        ``pose`` into the active submaps, each with its node-in-submap constraint, and start a
        new submap when the newest is half full or the robot has left it. Returns the submap
        that finished, if any."""
        p = self.params
        for s in self.active:
            local = relative(self._graph.poses[s.graph_id], pose)
            s.grid.insert(
                local[:2], transform_points(local, points), transform_points(local, misses)
            )
            s.nodes += 1
            self._graph.add_constraint(
                s.graph_id, node_id, local, p.constraint_sigma_xy, p.constraint_sigma_theta
            )
        newest = self.active[-1]
        newest_pose = self._graph.poses[newest.graph_id]
        far = math.hypot(*(pose[:2] - newest_pose[:2])) > 0.5 * p.submap_travel
        if newest.nodes >= max(1, p.submap_nodes // 2) or far:
            return self.start(pose)
        return None

    def drop(self, s: Submap) -> None:
        """Drop the finished submap ``s`` (never rendered into the composed map: it is dropped
        as it finishes); its pose stays in the graph."""
        self.all.remove(s)
        self.trimmed += 1

    def field(self, submap: Submap) -> LikelihoodField:
        """The submap's likelihood field, rebuilt every ``field_refresh_nodes`` nodes while the
        submap is being filled."""
        p = self.params
        if submap.field is None or (
            not submap.finished and submap.nodes - submap.field_nodes >= p.field_refresh_nodes
        ):
            submap.field = LikelihoodField(submap.grid, p.match_sigma)
            submap.field_nodes = submap.nodes
        return submap.field

    def box(self, s: Submap) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned map-frame bounds (lo, hi) of the submap's observed cells."""
        r0, r1, c0, c1 = s.grid.touched
        res = s.grid.resolution
        ox, oy = s.grid.origin
        corners = np.array(
            [[ox + c * res, oy + r * res] for r in (r0, r1) for c in (c0, c1)], dtype=float
        )
        world = transform_points(self._graph.poses[s.graph_id], corners)
        return world.min(axis=0), world.max(axis=0)

    def refresh(self, changed: list[Submap]) -> None:
        """The finished submaps ``changed`` had their grids changed: the map is composed anew."""
        if changed:
            self._cache = None

    def moved(self) -> None:
        """The graph was optimized: the finished submaps must be composed anew."""
        self._cache = None

    def occupancy(self, position: tuple[float, float]) -> SlamMap:
        """The map in the map frame: finished submaps (cached) plus the active ones; one empty
        tile at ``position`` before anything was observed."""
        p = self.params
        boxes = [self.box(s) for s in self.all if s.grid.touched is not None]
        tile = p.map_tile * p.resolution
        if not boxes:
            return SlamMap(
                np.zeros((p.map_tile, p.map_tile), dtype=np.float32), p.resolution, position
            )
        shift = self.lattice
        lo = np.floor((np.min([b[0] for b in boxes], axis=0) - shift) / tile) * tile + shift
        hi = np.ceil((np.max([b[1] for b in boxes], axis=0) - shift) / tile) * tile + shift
        origin = (float(lo[0]), float(lo[1]))
        shape = (
            round((hi[1] - lo[1]) / p.resolution),
            round((hi[0] - lo[0]) / p.resolution),
        )
        cache = self._cache
        if cache is None or cache.origin != origin or cache.log_odds.shape != shape:
            cache = self._cache = _MapCache(origin, np.zeros(shape, dtype=np.float32))
        for s in self.all:
            if s.finished and s.index not in cache.submaps:
                self._render(s, cache.log_odds, origin)
                cache.submaps.add(s.index)
        out = cache.log_odds.copy()
        for s in self.active:
            self._render(s, out, origin)
        np.clip(out, log_odds(p.p_min), log_odds(p.p_max), out=out)
        return SlamMap(out, p.resolution, origin)

    def _render(self, s: Submap, target: np.ndarray, origin: tuple[float, float]) -> None:
        """Add half the submap's log-odds into ``target`` (every node lives in two submaps),
        sampling the submap at the centre of each target cell it covers."""
        if s.grid.touched is None:
            return
        res = self.params.resolution
        lo, hi = self.box(s)
        rows, cols = target.shape
        c0 = max(math.floor((lo[0] - origin[0]) / res), 0)
        c1 = min(math.ceil((hi[0] - origin[0]) / res), cols)
        r0 = max(math.floor((lo[1] - origin[1]) / res), 0)
        r1 = min(math.ceil((hi[1] - origin[1]) / res), rows)
        if r0 >= r1 or c0 >= c1:
            return
        ys = origin[1] + (np.arange(r0, r1) + 0.5) * res
        xs = origin[0] + (np.arange(c0, c1) + 0.5) * res
        gx, gy = np.meshgrid(xs, ys)
        pose = self._graph.poses[s.graph_id]
        c, sn = math.cos(pose[2]), math.sin(pose[2])
        dx, dy = gx - pose[0], gy - pose[1]
        lx, ly = c * dx + sn * dy, -sn * dx + c * dy
        gc = np.floor((lx - s.grid.origin[0]) / res).astype(np.int64)
        gr = np.floor((ly - s.grid.origin[1]) / res).astype(np.int64)
        tr0, tr1, tc0, tc1 = s.grid.touched
        ok = (gr >= tr0) & (gr < tr1) & (gc >= tc0) & (gc < tc1)
        block = target[r0:r1, c0:c1]
        block[ok] += 0.5 * s.grid.log_odds[gr[ok], gc[ok]]
