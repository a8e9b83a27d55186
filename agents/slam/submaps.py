"""The SLAM's submaps (Hess et al. 2016): small occupancy grids, each anchored at a pose of the
pose graph, and the map composed from them.

Each node is inserted into the two active submaps (each receives ``submap_nodes`` nodes; a new
one starts every ``submap_nodes/2`` nodes, or once the robot is ``submap_travel/2`` from where
the newest one started), so the older one, which tracking matches against, is always well
filled. When a third starts, the oldest is finished: cropped to what it observed, with its
likelihood field built once for loop-closure searches.

Every submap's grid runs along the walls: turned by the heading of the walls the first scan
saw (:func:`cell_heading`: not where those walls are a raster's staircases of cells) and with
its cell lattice where they fall on cell centres (:func:`wall_lattice`). Matching a scan then
snaps it back onto the walls the map already holds, where with walls off the grid's axes
each match's few millimetres and tenths of a degree were inserted into the map and carried
on from submap to submap (docs/notes/slam.md, "Walls off the map's axes"). The composed map
is in the map frame, sampled from the submaps at each of its cells' centres.
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
    along it spread over every phase and cancel in the mean. Walls off the axes would cancel on
    both: ``Slam`` gives it the points turned by the walls' heading (:func:`wall_heading`).
    """
    phase = 2.0 * np.pi / resolution * np.asarray(points, dtype=float)
    mean = np.exp(1j * phase).sum(axis=0)
    centre = np.angle(mean) / (2.0 * np.pi) * resolution
    return np.mod(centre + 0.5 * resolution, resolution)


# chords between a scan's points this long (m) vote for the walls' direction (wall_heading) ...
CHORD_M = (0.2, 1.5)
# ... between points at most this many beams apart
CHORD_BEAMS = 40
# ... in bins of this width (rad); the peak bin's estimate is refined by Tukey's biweight of
# this scale (rad), the chords weighed by their length squared (the inverse of their
# direction's variance under range noise)
VOTE_BIN = math.radians(1.0)
VOTE_SCALE = math.radians(6.0)
VOTE_ITERATIONS = 20
# a heading within this (rad) of the map's axes is taken as on them: it is the estimate's error
# on one scan (0.11° at worst on 48 first scans of the built-in worlds, turned or not), and a map
# frame given with the robot's start is often a floor plan's, drawn along the walls
ON_AXES = math.radians(0.15)


def wall_heading(points: np.ndarray) -> float:
    """The heading (rad, in [−π/4, π/4]) of the frame whose axes the walls of a scan's
    map-frame ``points`` (N, 2, in beam order) run along, so that the map's cells can follow
    them (a robot maps a home in the frame it started in: its walls need run along no axis).

    The chords between points up to ``CHORD_BEAMS`` beams apart and ``CHORD_M`` long vote for
    their direction modulo a right angle, weighed by their length squared: the peak of the
    votes in ``VOTE_BIN`` bins, refined by an M-estimate with Tukey's biweight of scale
    ``VOTE_SCALE`` (iteratively reweighted mean of the directions' residuals), so that furniture
    standing at other angles does not pull it. 0 without such chords, and within ``ON_AXES`` of
    the map's axes."""
    pts = np.asarray(points, dtype=float)
    if len(pts) < 3:
        return 0.0
    beams = range(1, min(CHORD_BEAMS, len(pts) - 1) + 1)
    chords = np.concatenate([pts[k:] - pts[:-k] for k in beams])
    length = np.hypot(*chords.T)
    use = (length >= CHORD_M[0]) & (length <= CHORD_M[1])
    if not use.any():
        return 0.0
    alpha = np.mod(np.arctan2(chords[use, 1], chords[use, 0]), math.pi / 2)
    weight = length[use] ** 2
    bins = round((math.pi / 2) / VOTE_BIN)
    votes = np.bincount(np.minimum((alpha / VOTE_BIN).astype(np.int64), bins - 1), weight, bins)
    heading = (int(np.argmax(votes)) + 0.5) * VOTE_BIN
    for _ in range(VOTE_ITERATIONS):
        r = np.remainder(alpha - heading + math.pi / 4, math.pi / 2) - math.pi / 4
        w = weight * np.clip(1.0 - (r / VOTE_SCALE) ** 2, 0.0, None) ** 2
        step = float((w * r).sum() / max(w.sum(), 1e-12))
        heading += step
        if abs(step) < 1e-7:
            break
    heading = math.remainder(heading, math.pi / 2)
    return 0.0 if abs(heading) < ON_AXES else heading


def lattice_fit(points: np.ndarray, heading: float, resolution: float) -> float:
    """How closely map-frame ``points`` (N, 2) lie on the lines of one lattice of cells of
    ``resolution`` in the frame turned by ``heading``: per axis the mean resultant length of
    the points' phases (their coordinate modulo the cell, as an angle), summed over both axes.
    Points on lattice lines up to a range noise well under a cell score up to 1 an axis
    (wrapped normal: exp(−2π²σ²/res²), 0.45 at 1 cm on 5 cm cells) in proportion to the share
    of them on that axis's lines; points at random phases ≈ 1/√N."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(pts) == 0:
        return 0.0
    turned = transform_points(np.array([0.0, 0.0, -heading]), pts)
    return float(np.abs(np.exp(2j * math.pi * turned / resolution).mean(axis=0)).sum())


def cell_heading(points: np.ndarray, resolution: float) -> float:
    """The heading to turn the map's cells by for a first scan's map-frame ``points``: the
    walls' (:func:`wall_heading`), unless the points lie on the map's own lattice at least as
    closely as on the walls' (:func:`lattice_fit`). That is a world drawn on a raster, as a
    floor-plan image is: its walls off the axes are staircases of whole cells, which cells on
    the raster hold exactly and cells turned to the walls blur by half a cell (on the recorded
    apartment the turned cells' fit was 0.05–0.17 against 0.5–0.7 on the raster's, and the
    slam bench's ATE 76 mm against 22 mm). A straight wall off the axes fits the turned
    lattice (0.4–0.65 on the home turned by 20°) and not the map's (0.04–0.16)."""
    heading = wall_heading(points)
    if heading == 0.0 or lattice_fit(points, 0.0, resolution) >= lattice_fit(
        points, heading, resolution
    ):
        return 0.0
    return heading


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
        # Cell boundaries of the submaps lie at k·resolution + lattice (per axis of the frame
        # turned by ``heading`` from the map's): by default (k + ½)·resolution along the map's
        # axes, so walls on round coordinates fall on cell centres; ``Slam`` turns them to the
        # walls its first scan sees and puts them where those fall on centres
        # (:func:`cell_heading`, :func:`wall_lattice`).
        self.lattice = np.full(2, 0.5 * params.resolution)
        self.heading = 0.0
        # the composed map's cell boundaries (map frame): the submaps' lattice unless a saved
        # map's is to be kept (``Slam``)
        self.composed_lattice: np.ndarray | None = None

    def start(self, pose: np.ndarray) -> Submap | None:
        """Start a submap at ``pose``'s position, its grid turned by ``heading`` from the map
        frame (along the walls) and snapped to the cell lattice: all submaps then quantize a
        wall into the same cells, so the discretization bias does not differ (and accumulate)
        between submaps. Returns the submap this finished, if any."""
        p = self.params
        shift = self.lattice
        c, s = math.cos(self.heading), math.sin(self.heading)
        u = np.array([c * pose[0] + s * pose[1], -s * pose[0] + c * pose[1]])
        u = np.round((u - shift) / p.resolution) * p.resolution + shift
        snapped = np.array([c * u[0] - s * u[1], s * u[0] + c * u[1], self.heading])
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
        old.field = LikelihoodField(old.grid, p.match_sigma, p.loop_field_sectors)
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
        shift = self.lattice if self.composed_lattice is None else self.composed_lattice
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
