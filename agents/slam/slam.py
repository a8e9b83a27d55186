"""2D laser SLAM: scan-to-submap tracking and submap pose-graph loop closure (Hess et al. 2016).

Per scan, the odometry delta since the previous scan predicts the pose, and the correlative
matcher (Olson 2009) aligns the scan with the older of the two active submaps around that
prediction. Scans that moved enough become *nodes*: they are inserted into both active submaps
(each submap receives ``submap_nodes`` nodes; a new one starts every ``submap_nodes/2``), so
the matching submap is always well filled. Nodes and submaps are poses of a pose graph with
constraints node-in-submap (from tracking), node-to-node (odometry) and loop closures (a node
matched against an older finished submap near its estimate). After new loop closures the graph
is optimized with sparse least squares and the current pose follows the last node's correction.

The map frame is the frame of ``initial_pose``: an agent that knows its dock pose in the world
passes it, and the SLAM map is then in world coordinates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from agents.slam.geometry import (
    compose,
    inverse,
    relative,
    scan_to_points,
    transform_points,
    wrap_angle,
)
from agents.slam.matcher import CorrelativeMatcher, LikelihoodField
from agents.slam.motion import prior_penalties, step_sigmas
from agents.slam.occupancy import LogOddsGrid, log_odds
from agents.slam.pose_graph import PoseGraph
from agents.slam.slam_map import SlamMap
from fleet.slam_params import SlamParams

Pose = tuple[float, float, float]


@dataclass(frozen=True, eq=False)
class SlamEstimate:
    """The pose after a scan (map frame), its 3×3 covariance (x, y, θ) and the scan time.

    ``matched`` is False when the scan could not be aligned (too few returns or a score below
    ``min_match_score``) and the pose is odometry-propagated only.
    """

    pose: Pose
    covariance: np.ndarray
    t: float
    matched: bool
    score: float


@dataclass(frozen=True)
class SlamStats:
    scans: int
    nodes: int
    submaps: int
    loop_closures: int
    optimizations: int


@dataclass(eq=False)
class _Submap:
    index: int
    graph_id: int
    grid: LogOddsGrid
    nodes: int = 0
    finished: bool = False
    field: LikelihoodField | None = None
    field_nodes: int = -1


@dataclass(frozen=True, eq=False)
class _Closure:
    """A loop-closure match: node ``node_id`` seen from submap ``submap_graph_id`` at ``pose``;
    ``correction`` is the map-frame rigid motion it implies for the node's estimate."""

    node_id: int
    submap_graph_id: int
    pose: np.ndarray
    correction: np.ndarray
    nodes_then: int  # the SLAM's node count when it was found


@dataclass(eq=False)
class _MapCache:
    origin: tuple[float, float]
    log_odds: np.ndarray
    submaps: set[int] = field(default_factory=set)


class Slam:
    """Online SLAM for one robot. Feed every scan to ``process``; read ``occupancy()`` for the map.

    ``range_min``/``range_max`` are the sensor's limits; returns outside [range_min, range_max)
    (and beyond ``params.max_range``) are treated as "no return" and skipped entirely: no free
    space is carved along them. With ``keep_trajectory`` every scan's pose is remembered relative
    to its node, and ``trajectory()`` returns them all as corrected by the latest optimization.
    """

    def __init__(
        self,
        params: SlamParams,
        initial_pose: Pose = (0.0, 0.0, 0.0),
        range_min: float = 0.0,
        range_max: float = math.inf,
        keep_trajectory: bool = False,
    ) -> None:
        self.params = params
        self._keep_trajectory = keep_trajectory
        self._anchor_ids: list[int] = []
        self._anchor_offsets: list[np.ndarray] = []
        self.range_min = range_min
        self.range_max = min(range_max, params.max_range)
        self._matcher = CorrelativeMatcher(params)
        self._graph = PoseGraph()
        self._submaps: list[_Submap] = []
        self._active: list[_Submap] = []
        self._pose = np.asarray(initial_pose, dtype=float)
        self._last_odom: np.ndarray | None = None
        self._last_node_id: int | None = None
        self._last_node_odom: np.ndarray | None = None
        self._last_node_t = -math.inf
        self._covariance = np.zeros((3, 3))
        self._scans = 0
        self._nodes = 0
        self._loop_closures = 0
        self._pending_loops = 0
        # Odometry uncertainty accumulated since the last loop closure (variances, m² and rad²)
        # and a closure waiting for a second one that agrees (see _close_loops).
        self._drift_var_xy = 0.0
        self._drift_var_theta = 0.0
        self._unconfirmed: _Closure | None = None
        self._nodes_since_optimization = 0
        self._optimizations = 0
        self._cache: _MapCache | None = None
        self._half_size = self.range_max + params.submap_travel
        # Cell boundaries of the map lie at (k + ½)·resolution, so walls drawn on round
        # coordinates fall on cell centres. A wall on a boundary is split between two cells by
        # range noise, and matching then settles it into one cell, shifting the map half a cell.
        self._lattice_offset = 0.5 * params.resolution

    @property
    def pose(self) -> Pose:
        return (float(self._pose[0]), float(self._pose[1]), float(self._pose[2]))

    def stats(self) -> SlamStats:
        return SlamStats(
            self._scans, self._nodes, len(self._submaps), self._loop_closures, self._optimizations
        )

    def process(
        self,
        scan_ranges: np.ndarray,
        angle_min: float,
        angle_increment: float,
        odom_pose: Pose,
        t: float,
    ) -> SlamEstimate:
        """One scan with the odometry pose (odometry frame, absolute) at the scan's time."""
        p = self.params
        points = scan_to_points(
            scan_ranges, angle_min, angle_increment, self.range_min, self.range_max
        )
        odom = np.asarray(odom_pose, dtype=float)
        self._scans += 1
        if self._last_odom is None:
            self._last_odom = odom
            self._add_node(points, odom, t)
            self._remember_pose()
            return SlamEstimate(self.pose, self._covariance.copy(), t, True, 1.0)
        step = relative(self._last_odom, odom)
        prior = compose(self._pose, step)
        self._last_odom = odom
        submap = self._active[0]
        matched, score = False, 0.0
        if points.shape[0] >= 3 and submap.grid.touched is not None:
            fld = self._field(submap)
            sm_pose = self._graph.poses[submap.graph_id]
            result = self._matcher.match(
                fld,
                points,
                relative(sm_pose, prior),
                p.search_window_xy,
                p.search_window_theta,
                p.coarse_factor,
                penalties=prior_penalties(p, step),
            )
            score = result.score
            matched = score >= p.min_match_score
            if matched:
                prior = compose(sm_pose, result.pose)
                self._covariance = _rotate_covariance(result.covariance, sm_pose[2])
        if not matched:
            self._covariance = np.diag(
                [p.search_window_xy**2, p.search_window_xy**2, p.search_window_theta**2]
            )
        self._pose = prior
        if self._is_new_node(odom, t):
            self._add_node(points, odom, t)
        self._remember_pose()
        return SlamEstimate(self.pose, self._covariance.copy(), t, matched, score)

    def trajectory(self) -> np.ndarray:
        """(scans, 3) poses of every processed scan after the latest graph optimization."""
        if not self._keep_trajectory:
            raise RuntimeError("construct Slam with keep_trajectory=True to read trajectory()")
        if not self._anchor_ids:
            return np.zeros((0, 3))
        nodes = self._graph.poses[np.asarray(self._anchor_ids)]
        return compose(nodes, np.asarray(self._anchor_offsets))

    def _remember_pose(self) -> None:
        if self._keep_trajectory:
            self._anchor_ids.append(self._last_node_id)
            self._anchor_offsets.append(relative(self._graph.poses[self._last_node_id], self._pose))

    def finish(self) -> None:
        """Optimize once more if loop closures came in since the last optimization."""
        if self._pending_loops:
            self._optimize()

    def occupancy(self) -> SlamMap:
        """The map in the map frame: finished submaps (cached) plus the active ones."""
        p = self.params
        boxes = [self._submap_box(s) for s in self._submaps if s.grid.touched is not None]
        tile = p.map_tile * p.resolution
        if not boxes:
            return SlamMap(
                np.zeros((p.map_tile, p.map_tile), dtype=np.float32),
                p.resolution,
                (float(self._pose[0]), float(self._pose[1])),
            )
        shift = self._lattice_offset
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
        for s in self._submaps:
            if s.finished and s.index not in cache.submaps:
                self._render(s, cache.log_odds, origin)
                cache.submaps.add(s.index)
        out = cache.log_odds.copy()
        for s in self._active:
            self._render(s, out, origin)
        np.clip(out, log_odds(p.p_min), log_odds(p.p_max), out=out)
        return SlamMap(out, p.resolution, origin)

    def _field(self, submap: _Submap) -> LikelihoodField:
        p = self.params
        if submap.field is None or (
            not submap.finished and submap.nodes - submap.field_nodes >= p.field_refresh_nodes
        ):
            submap.field = LikelihoodField(submap.grid, p.match_sigma)
            submap.field_nodes = submap.nodes
        return submap.field

    def _is_new_node(self, odom: np.ndarray, t: float) -> bool:
        p = self.params
        moved = relative(self._last_node_odom, odom)
        return (
            math.hypot(moved[0], moved[1]) >= p.node_min_distance
            or abs(moved[2]) >= p.node_min_rotation
            or t - self._last_node_t >= p.node_max_interval
        )

    def _new_submap(self, pose: np.ndarray) -> None:
        """Start a submap at ``pose``'s position, its grid axis-aligned with the map frame and
        snapped to the map's cell lattice: all submaps then quantize a wall into the same cells,
        so the discretization bias does not differ (and accumulate) between submaps, and the
        map is composed from them without resampling across lattices."""
        p = self.params
        shift = self._lattice_offset
        snapped = np.array(
            [
                round((pose[0] - shift) / p.resolution) * p.resolution + shift,
                round((pose[1] - shift) / p.resolution) * p.resolution + shift,
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
        submap = _Submap(len(self._submaps), self._graph.add_pose(snapped), grid)
        self._submaps.append(submap)
        self._active.append(submap)
        if len(self._active) > 2:
            old = self._active.pop(0)
            old.finished = True
            margin = math.ceil(max(p.loop_window_xy, 3.0 * p.match_sigma) / p.resolution) + 1
            old.grid = old.grid.cropped(margin)
            old.field = LikelihoodField(old.grid, p.match_sigma)
            old.field_nodes = old.nodes

    def _add_node(self, points: np.ndarray, odom: np.ndarray, t: float) -> None:
        p = self.params
        pose = self._pose
        if not self._submaps:
            self._new_submap(pose)
        node_id = self._graph.add_pose(pose)
        if self._last_node_id is not None:
            step = relative(self._last_node_odom, odom)
            self._graph.add_constraint(
                self._last_node_id, node_id, step, p.odom_sigma_xy, p.odom_sigma_theta
            )
            self._accumulate_drift(step)
        for s in self._active:
            local = relative(self._graph.poses[s.graph_id], pose)
            s.grid.insert(local[:2], transform_points(local, points))
            s.nodes += 1
            self._graph.add_constraint(
                s.graph_id, node_id, local, p.constraint_sigma_xy, p.constraint_sigma_theta
            )
        self._last_node_id = node_id
        self._last_node_odom = odom
        self._last_node_t = t
        self._nodes += 1
        self._nodes_since_optimization += 1
        newest = self._active[-1]
        newest_pose = self._graph.poses[newest.graph_id]
        far = math.hypot(*(pose[:2] - newest_pose[:2])) > 0.5 * p.submap_travel
        if newest.nodes >= max(1, p.submap_nodes // 2) or far:
            self._new_submap(pose)
        if self._nodes % p.loop_every_nodes == 0 and points.shape[0] >= 3:
            self._close_loops(node_id, points)
        if self._pending_loops and self._nodes_since_optimization >= p.optimize_every_nodes:
            self._optimize()

    def _accumulate_drift(self, step: np.ndarray) -> None:
        """Grow the uncertainty since the last closure by one odometry step (the motion model
        of ``agents.slam.motion``; a heading error σ_θ moves the position by σ_θ·dd, first-order
        propagation)."""
        dd = math.hypot(step[0], step[1])
        sigma_xy, sigma_theta = step_sigmas(self.params, step)
        self._drift_var_xy += sigma_xy**2 + self._drift_var_theta * dd**2
        self._drift_var_theta += sigma_theta**2

    def _loop_windows(self) -> tuple[float, float]:
        """Search half-widths (m, rad): loop_window_sigmas standard deviations of the drift
        since the last closure, within [loop_window_xy, loop_window_max_xy] (and theta)."""
        p = self.params
        k = p.loop_window_sigmas
        xy = min(max(p.loop_window_xy, k * math.sqrt(self._drift_var_xy)), p.loop_window_max_xy)
        theta = min(
            max(p.loop_window_theta, k * math.sqrt(self._drift_var_theta)),
            p.loop_window_max_theta,
        )
        return xy, theta

    def _close_loops(self, node_id: int, points: np.ndarray) -> None:
        """Match the node against finished submaps near it (Hess et al. 2016 §V), in a window
        that grows with the drift since the last closure. A match close to the estimate (within
        loop_window_xy / loop_window_theta) is added at once; one further off, found only
        thanks to the grown window, is held until a second match within loop_confirm_nodes
        nodes implies the same rigid correction of the trajectory (a wrong match in a building
        of similar corridors rarely repeats consistently), then both are added. A match that
        moves the estimate by more than loop_agree_xy / loop_agree_theta is dropped when a
        distinct candidate scores within loop_ambiguity_margin of it: a wall drawn as a
        staircase (a recorded map's off-axis wall) or a straight wall that the scan sees beyond
        the submap's end fits the submap one step along it as well, or better, and such
        closures repeat consistently, so confirmation does not catch them."""
        p = self.params
        pose = self._graph.poses[node_id]
        window_xy, window_theta = self._loop_windows()
        radius = p.loop_search_radius + window_xy
        newest_allowed = self._active[0].index - p.loop_min_submap_gap
        if self._unconfirmed is not None and self._nodes - self._unconfirmed.nodes_then > (
            p.loop_confirm_nodes
        ):
            self._unconfirmed = None
        candidates = []
        for s in self._submaps:
            if not s.finished or s.index > newest_allowed or s.grid.touched is None:
                continue
            lo, hi = self._submap_box(s)
            gap = np.maximum(np.maximum(lo - pose[:2], pose[:2] - hi), 0.0)
            distance = float(np.hypot(*gap))
            if distance <= radius:
                candidates.append((distance, s))
        candidates.sort(key=lambda c: c[0])
        for _, s in candidates[: p.loop_max_candidates]:
            sm_pose = self._graph.poses[s.graph_id]
            result = self._matcher.match(
                s.field,
                points,
                relative(sm_pose, pose),
                window_xy,
                window_theta,
                p.loop_coarse_factor,
                penalize=False,
                search_points=p.loop_search_points,
                max_coarse=p.loop_max_coarse,
                distinct=(p.loop_agree_xy, p.loop_agree_theta),
                rival_margin=p.loop_ambiguity_margin,
            )
            if result.score < p.loop_min_score:
                continue
            matched = compose(sm_pose, result.pose)
            off = relative(pose, matched)
            if result.rival_gap < p.loop_ambiguity_margin and self._surprising(off):
                continue
            closure = _Closure(
                node_id, s.graph_id, result.pose, compose(matched, inverse(pose)), self._nodes
            )
            near = math.hypot(off[0], off[1]) <= p.loop_window_xy and abs(off[2]) <= (
                p.loop_window_theta
            )
            if near:
                self._add_closure(closure)
            elif self._unconfirmed is not None and self._agrees(self._unconfirmed, closure):
                self._add_closure(self._unconfirmed)
                self._add_closure(closure)
                self._unconfirmed = None
            else:
                self._unconfirmed = closure

    def _surprising(self, off: np.ndarray) -> bool:
        """Whether a closure's offset ``off`` from the estimate (dx, dy, dθ in the node's frame)
        exceeds loop_agree_xy or loop_agree_theta: it would move the robot by more than two
        closures may disagree by."""
        p = self.params
        return math.hypot(off[0], off[1]) > p.loop_agree_xy or abs(off[2]) > p.loop_agree_theta

    def _agrees(self, a: _Closure, b: _Closure) -> bool:
        """Whether two closures imply the same rigid correction: moved by each, the later node
        lands within loop_agree_xy, and the rotations differ by at most loop_agree_theta."""
        p = self.params
        node = self._graph.poses[b.node_id]
        gap = compose(a.correction, node)[:2] - compose(b.correction, node)[:2]
        turn = abs(float(wrap_angle(a.correction[2] - b.correction[2])))
        return math.hypot(gap[0], gap[1]) <= p.loop_agree_xy and turn <= p.loop_agree_theta

    def _add_closure(self, closure: _Closure) -> None:
        p = self.params
        self._graph.add_constraint(
            closure.submap_graph_id,
            closure.node_id,
            closure.pose,
            p.loop_sigma_xy,
            p.loop_sigma_theta,
        )
        self._loop_closures += 1
        self._pending_loops += 1
        self._drift_var_xy = 0.0
        self._drift_var_theta = 0.0

    def _optimize(self) -> None:
        before = self._graph.poses[self._last_node_id].copy()
        self._graph.optimize(self.params.huber_scale)
        after = self._graph.poses[self._last_node_id]
        self._pose = compose(after, relative(before, self._pose))
        self._pending_loops = 0
        self._nodes_since_optimization = 0
        self._optimizations += 1
        self._cache = None

    def _submap_box(self, s: _Submap) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned map-frame bounds (lo, hi) of the submap's observed cells."""
        r0, r1, c0, c1 = s.grid.touched
        res = s.grid.resolution
        ox, oy = s.grid.origin
        corners = np.array(
            [[ox + c * res, oy + r * res] for r in (r0, r1) for c in (c0, c1)], dtype=float
        )
        world = transform_points(self._graph.poses[s.graph_id], corners)
        return world.min(axis=0), world.max(axis=0)

    def _render(self, s: _Submap, target: np.ndarray, origin: tuple[float, float]) -> None:
        """Add half the submap's log-odds into ``target`` (every node lives in two submaps),
        sampling the submap at the centre of each target cell it covers."""
        if s.grid.touched is None:
            return
        res = self.params.resolution
        lo, hi = self._submap_box(s)
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


def _rotate_covariance(cov: np.ndarray, theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return rot @ cov @ rot.T
