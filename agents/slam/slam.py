"""2D laser SLAM: scan-to-submap tracking and submap pose-graph loop closure (Hess et al. 2016).

Per scan, the odometry delta since the previous scan predicts the pose, and the correlative
matcher (Olson 2009) aligns the scan with the older of the two active submaps around that
prediction. Scans that moved enough become *nodes*: they are inserted into both active submaps
(``agents.slam.submaps``), so the matching submap is always well filled. Nodes and submaps are
poses of a pose graph with constraints node-in-submap (from tracking), node-to-node (odometry)
and loop closures (``agents.slam.loop_closure``: a node matched against an older finished
submap near its estimate). After new loop closures the graph is optimized with sparse least
squares and the current pose follows the last node's correction. A finished submap that adds
almost nothing to the older ones (``agents.slam.trimmer``) is dropped, its grid and likelihood
field with it, so a robot cleaning the same floor for hours keeps a bounded number of submaps.

The map frame is the frame of ``initial_pose``: an agent that knows its dock pose in the world
passes it, and the SLAM map is then in world coordinates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agents.slam.geometry import (
    compose,
    missing_rays,
    relative,
    scan_to_points,
    transform_points,
)
from agents.slam.loop_closure import LoopCloser
from agents.slam.matcher import CorrelativeMatcher
from agents.slam.motion import prior_penalties, tracking_window, within_refinement
from agents.slam.occupancy import log_odds
from agents.slam.pose_graph import PoseGraph
from agents.slam.slam_map import SlamMap
from agents.slam.submaps import Submap, Submaps, cell_heading, map_lattice, wall_lattice
from agents.slam.trimmer import cover, fold
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
    """Counts of the work done: scans processed, pose-graph nodes, submaps, loop closures,
    optimizations, submaps trimmed, and scans placed by the correlative search (the others
    matched were placed by the refinement alone)."""

    scans: int
    nodes: int
    submaps: int
    loop_closures: int
    optimizations: int
    trimmed: int = 0
    searches: int = 0


class Slam:
    """Online SLAM for one robot. Feed every scan to ``process``; read ``occupancy()`` for the map.

    ``range_min``/``range_max`` are the sensor's limits; returns outside [range_min, range_max)
    (and beyond ``params.max_range``) are treated as "no return": no hit, and free space only
    along the first ``params.missing_ray_length`` of a beam that saw nothing within the range.
    With ``keep_trajectory`` every scan's pose is remembered relative to its node, and
    ``trajectory()`` returns them all as corrected by the latest optimization. The submaps'
    cells are turned to the walls the first scan sees and their boundaries put where those
    walls fall on cell centres (``cell_heading``, ``wall_lattice``); a given ``lattice`` (x, y
    offsets, e.g. a saved map's, ``map_lattice``) is where the composed map's cell boundaries
    lie, and the submaps' too when the walls run along the map's axes.
    """

    def __init__(
        self,
        params: SlamParams,
        initial_pose: Pose = (0.0, 0.0, 0.0),
        range_min: float = 0.0,
        range_max: float = math.inf,
        keep_trajectory: bool = False,
        lattice: tuple[float, float] | None = None,
    ) -> None:
        self.params = params
        self._lattice = lattice
        self._keep_trajectory = keep_trajectory
        self._anchor_ids: list[int] = []
        self._anchor_offsets: list[np.ndarray] = []
        self.range_min = range_min
        self.range_max = min(range_max, params.max_range)
        self._matcher = CorrelativeMatcher(params)
        self._graph = PoseGraph(params.optimize_window_nodes)
        self._submaps = Submaps(params, self._graph, self.range_max)
        self._loops = LoopCloser(params, self._graph)
        self._pose = np.asarray(initial_pose, dtype=float)
        self._last_odom: np.ndarray | None = None
        self._last_node_id: int | None = None
        self._last_node_odom: np.ndarray | None = None
        self._last_node_t = -math.inf
        self._covariance = np.zeros((3, 3))
        self._since_search = 0
        self._last_score: float | None = None
        self._scans = 0
        self._searches = 0
        self._nodes = 0
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
            self._loops.closures,
            self._optimizations,
            self._submaps.trimmed,
            self._searches,
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
            self._add_node(points, self._misses(scan_ranges, angle_min, angle_increment), odom, t)
            self._remember_pose()
            return SlamEstimate(self.pose, self._covariance.copy(), t, True, 1.0)
        step = relative(self._last_odom, odom)
        prior = compose(self._pose, step)
        self._last_odom = odom
        submap = self._submaps.active[0]
        matched, score = False, 0.0
        if points.shape[0] >= 3 and submap.grid.touched is not None:
            prior, score = self._track(submap, points, prior, step)
            matched = score >= p.min_match_score
            self._last_score = score if matched else None
        if not matched:
            self._covariance = np.diag(
                [p.search_window_xy**2, p.search_window_xy**2, p.search_window_theta**2]
            )
        self._pose = prior
        if self._is_new_node(odom, t):
            self._add_node(points, self._misses(scan_ranges, angle_min, angle_increment), odom, t)
        self._remember_pose()
        return SlamEstimate(self.pose, self._covariance.copy(), t, matched, score)

    def _track(
        self, submap: Submap, points: np.ndarray, prior: np.ndarray, step: np.ndarray
    ) -> tuple[np.ndarray, float]:
        """The scan's pose (map frame) and score against the matching ``submap``: the
        refinement alone from the odometry ``prior`` (``CorrelativeMatcher.track``), or the
        correlative search every ``track_search_every`` scans, for a step whose odometry may
        err beyond the fit's basin (``within_refinement``), and whenever that fit ends on its
        bound or scores ``track_score_drop`` below the last matched scan. A score under
        ``min_match_score`` leaves the prior as it was. The covariance is the last search's."""
        p = self.params
        fld = self._submaps.field(submap)
        sm_pose = self._graph.poses[submap.graph_id]
        local = relative(sm_pose, prior)
        penalties = prior_penalties(p, step)
        if (
            self._since_search < p.track_search_every - 1
            and self._last_score is not None
            and within_refinement(p, step)
        ):
            tracked = self._matcher.track(fld, points, local, penalties)
            if tracked is not None and tracked[1] >= self._last_score - p.track_score_drop:
                self._since_search += 1
                pose, score = tracked
                return (compose(sm_pose, pose) if score >= p.min_match_score else prior), score
        window_xy, window_theta = tracking_window(p, step)
        result = self._matcher.match(
            fld, points, local, window_xy, window_theta, p.coarse_factor, penalties=penalties
        )
        self._since_search = 0
        self._searches += 1
        if result.score < p.min_match_score:
            return prior, result.score
        self._covariance = _rotate_covariance(result.covariance, sm_pose[2])
        return compose(sm_pose, result.pose), result.score

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
        if self._loops.pending:
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

    def _misses(self, ranges: np.ndarray, angle_min: float, angle_increment: float) -> np.ndarray:
        """The ends of the scan's missing rays (only a node's scan is inserted into the map)."""
        length = min(self.params.missing_ray_length, self.range_max)
        return missing_rays(ranges, angle_min, angle_increment, self.range_max, length)

    def _first_submap(self, pose: np.ndarray, points: np.ndarray) -> None:
        """Turn the submaps' cells to the walls of the first scan (``cell_heading``: unless the
        walls are a raster's staircases) and put their lattice on those walls
        (``wall_lattice``), then start the first submap. A given
        ``lattice`` (a saved map's) keeps the composed map on its cells, so the new map can be
        laid over the saved one; the submaps take it too when the walls run along the map's
        axes, and keep their own turned lattice when they do not."""
        p = self.params
        heading, lattice = 0.0, None
        if points.shape[0] >= 3:
            seen = transform_points(pose, points)
            heading = cell_heading(seen, p.resolution)
            turned = transform_points(np.array([0.0, 0.0, -heading]), seen)
            lattice = wall_lattice(turned, p.resolution)
        if self._lattice is not None:
            self._submaps.composed_lattice = map_lattice(self._lattice, p.resolution)
            if heading == 0.0:
                lattice = self._submaps.composed_lattice
        if lattice is not None:
            self._submaps.heading = heading
            self._submaps.lattice = lattice
        self._submaps.start(pose)

    def _add_node(self, points: np.ndarray, misses: np.ndarray, odom: np.ndarray, t: float) -> None:
        p = self.params
        pose = self._pose
        if not self._submaps.all:
            self._first_submap(pose, points)
        node_id = self._graph.add_pose(pose)
        if self._last_node_id is not None:
            step = relative(self._last_node_odom, odom)
            self._graph.add_constraint(
                self._last_node_id, node_id, step, p.odom_sigma_xy, p.odom_sigma_theta
            )
            self._loops.accumulate_drift(step)
        finished = self._submaps.add_node(node_id, pose, points, misses)
        self._last_node_id = node_id
        self._last_node_odom = odom
        self._last_node_t = t
        self._nodes += 1
        self._nodes_since_optimization += 1
        if self._nodes % p.loop_every_nodes == 0 and points.shape[0] >= 3:
            self._loops.search(node_id, points, self._submaps, self._nodes)
        if self._loops.pending and self._nodes_since_optimization >= p.optimize_every_nodes:
            self._optimize()
        if finished is not None:
            self._trim(finished)

    def _trim(self, finished: Submap) -> None:
        """Drop the submap that just finished, its log-odds folded into the older ones, if
        older kept submaps hold at least ``trim_overlap`` of its walls. Its pose and its nodes
        stay in the pose graph with their constraints (a few dozen bytes each): dropping them
        cost accuracy (docs/notes/slam.md), while its grid and likelihood field are what
        weighs."""
        p = self.params
        older = [k for k in self._submaps.all if k.finished and k is not finished]
        covered = cover(finished, older, self._graph.poses, log_odds(p.occupied_threshold))
        if covered.share < p.trim_overlap:
            return
        self._submaps.refresh(fold(covered))
        self._submaps.drop(finished)

    def _optimize(self) -> None:
        before = self._graph.poses[self._last_node_id].copy()
        self._graph.optimize(self.params.huber_scale)
        after = self._graph.poses[self._last_node_id]
        self._pose = compose(after, relative(before, self._pose))
        self._loops.pending = 0
        self._nodes_since_optimization = 0
        self._optimizations += 1
        self._submaps.moved()


def _rotate_covariance(cov: np.ndarray, theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return rot @ cov @ rot.T
