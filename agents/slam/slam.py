"""2D laser SLAM: scan-to-submap tracking and submap pose-graph loop closure (Hess et al. 2016).

Per scan, the odometry delta since the previous scan predicts the pose, and the correlative
matcher (Olson 2009) aligns the scan with the older of the two active submaps around that
prediction. Scans that moved enough become *nodes*: they are inserted into both active submaps
(``agents.slam.submaps``), so the matching submap is always well filled. Nodes and submaps are
poses of a pose graph with constraints node-in-submap (from tracking), node-to-node (odometry)
and loop closures (a node matched against an older finished submap near its estimate). After
new loop closures the graph is optimized with sparse least squares and the current pose follows
the last node's correction.

The map frame is the frame of ``initial_pose``: an agent that knows its dock pose in the world
passes it, and the SLAM map is then in world coordinates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agents.slam.geometry import (
    compose,
    inverse,
    relative,
    scan_to_points,
    wrap_angle,
)
from agents.slam.matcher import CorrelativeMatcher
from agents.slam.motion import prior_penalties, step_sigmas
from agents.slam.pose_graph import PoseGraph
from agents.slam.slam_map import SlamMap
from agents.slam.submaps import Submaps
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


@dataclass(frozen=True, eq=False)
class _Closure:
    """A loop-closure match: node ``node_id`` seen from submap ``submap_graph_id`` at ``pose``;
    ``correction`` is the map-frame rigid motion it implies for the node's estimate."""

    node_id: int
    submap_graph_id: int
    pose: np.ndarray
    correction: np.ndarray
    nodes_then: int  # the SLAM's node count when it was found


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
        self._submaps = Submaps(params, self._graph, self.range_max)
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

    @property
    def pose(self) -> Pose:
        return (float(self._pose[0]), float(self._pose[1]), float(self._pose[2]))

    def stats(self) -> SlamStats:
        return SlamStats(
            self._scans,
            self._nodes,
            len(self._submaps.all),
            self._loop_closures,
            self._optimizations,
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
        submap = self._submaps.active[0]
        matched, score = False, 0.0
        if points.shape[0] >= 3 and submap.grid.touched is not None:
            fld = self._submaps.field(submap)
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
        return self._submaps.occupancy((float(self._pose[0]), float(self._pose[1])))

    def _is_new_node(self, odom: np.ndarray, t: float) -> bool:
        p = self.params
        moved = relative(self._last_node_odom, odom)
        return (
            math.hypot(moved[0], moved[1]) >= p.node_min_distance
            or abs(moved[2]) >= p.node_min_rotation
            or t - self._last_node_t >= p.node_max_interval
        )

    def _add_node(self, points: np.ndarray, odom: np.ndarray, t: float) -> None:
        p = self.params
        pose = self._pose
        if not self._submaps.all:
            self._submaps.start(pose)
        node_id = self._graph.add_pose(pose)
        if self._last_node_id is not None:
            step = relative(self._last_node_odom, odom)
            self._graph.add_constraint(
                self._last_node_id, node_id, step, p.odom_sigma_xy, p.odom_sigma_theta
            )
            self._accumulate_drift(step)
        self._submaps.add_node(node_id, pose, points)
        self._last_node_id = node_id
        self._last_node_odom = odom
        self._last_node_t = t
        self._nodes += 1
        self._nodes_since_optimization += 1
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
        newest_allowed = self._submaps.active[0].index - p.loop_min_submap_gap
        if self._unconfirmed is not None and self._nodes - self._unconfirmed.nodes_then > (
            p.loop_confirm_nodes
        ):
            self._unconfirmed = None
        candidates = []
        for s in self._submaps.all:
            if not s.finished or s.index > newest_allowed or s.grid.touched is None:
                continue
            lo, hi = self._submaps.box(s)
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
        self._submaps.moved()


def _rotate_covariance(cov: np.ndarray, theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return rot @ cov @ rot.T
