"""Loop-closure search: a node matched against the finished submaps near its estimate (Hess et
al. 2016 §V), in a window that grows with the odometry drift since the last closure, each match
checked before it becomes a constraint of the pose graph."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agents.slam.geometry import compose, inverse, relative, wrap_angle
from agents.slam.matcher import CorrelativeMatcher
from agents.slam.motion import step_sigmas
from agents.slam.pose_graph import PoseGraph
from agents.slam.submaps import Submap, Submaps
from fleet.slam_params import SlamParams


@dataclass(frozen=True, eq=False)
class Closure:
    """A loop-closure match: node ``node_id`` seen from submap ``submap_graph_id`` at ``pose``;
    ``correction`` is the map-frame rigid motion it implies for the node's estimate."""

    node_id: int
    submap_graph_id: int
    pose: np.ndarray
    correction: np.ndarray
    nodes_then: int  # the SLAM's node count when it was found


class LoopCloser:
    """Finds loop closures and adds them to ``graph``; ``closures`` counts them all, ``pending``
    those added since the SLAM last optimized the graph (it resets the count)."""

    def __init__(self, params: SlamParams, graph: PoseGraph) -> None:
        self.params = params
        self._graph = graph
        self._matcher = CorrelativeMatcher(params)
        self.closures = 0
        self.pending = 0
        # Odometry uncertainty accumulated since the last loop closure (variances, m² and rad²)
        # and a closure waiting for a second one that agrees (see search).
        self._drift_var_xy = 0.0
        self._drift_var_theta = 0.0
        self._unconfirmed: Closure | None = None

    def accumulate_drift(self, step: np.ndarray) -> None:
        """Grow the uncertainty since the last closure by one odometry step (the motion model
        of ``agents.slam.motion``; a heading error σ_θ moves the position by σ_θ·dd, first-order
        propagation)."""
        dd = math.hypot(step[0], step[1])
        sigma_xy, sigma_theta = step_sigmas(self.params, step)
        self._drift_var_xy += sigma_xy**2 + self._drift_var_theta * dd**2
        self._drift_var_theta += sigma_theta**2

    def windows(self) -> tuple[float, float]:
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

    def search(self, node_id: int, points: np.ndarray, submaps: Submaps, nodes: int) -> None:
        """Match node ``node_id`` (its scan ``points``; ``nodes`` the SLAM's node count) against
        finished submaps near it (Hess et al. 2016 §V), in a window that grows with the drift
        since the last closure. A match close to the estimate (within loop_window_xy /
        loop_window_theta) is added at once; one further off, found only thanks to the grown
        window, is held until a second match within loop_confirm_nodes nodes implies the same
        rigid correction of the trajectory (a wrong match in a building of similar corridors
        rarely repeats consistently), then both are added. A match that moves the estimate by
        more than loop_agree_xy / loop_agree_theta is dropped when a distinct candidate scores
        within loop_ambiguity_margin of it: a wall drawn as a staircase (a recorded map's
        off-axis wall) or a straight wall that the scan sees beyond the submap's end fits the
        submap one step along it as well, or better, and such closures repeat consistently, so
        confirmation does not catch them."""
        p = self.params
        pose = self._graph.poses[node_id]
        window_xy, window_theta = self.windows()
        if self._unconfirmed is not None and nodes - self._unconfirmed.nodes_then > (
            p.loop_confirm_nodes
        ):
            self._unconfirmed = None
        for s in self._candidates(pose, p.loop_search_radius + window_xy, submaps):
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
            closure = Closure(
                node_id, s.graph_id, result.pose, compose(matched, inverse(pose)), nodes
            )
            near = math.hypot(off[0], off[1]) <= p.loop_window_xy and abs(off[2]) <= (
                p.loop_window_theta
            )
            if near:
                self.add(closure)
            elif self._unconfirmed is not None and self.agrees(self._unconfirmed, closure):
                self.add(self._unconfirmed)
                self.add(closure)
                self._unconfirmed = None
            else:
                self._unconfirmed = closure

    def _candidates(self, pose: np.ndarray, radius: float, submaps: Submaps) -> list[Submap]:
        """The loop_max_candidates nearest finished submaps whose observed box lies within
        ``radius`` of ``pose``, leaving out the loop_min_submap_gap ones before the active."""
        p = self.params
        newest_allowed = submaps.active[0].index - p.loop_min_submap_gap
        candidates = []
        for s in submaps.all:
            if not s.finished or s.index > newest_allowed or s.grid.touched is None:
                continue
            lo, hi = submaps.box(s)
            gap = np.maximum(np.maximum(lo - pose[:2], pose[:2] - hi), 0.0)
            distance = float(np.hypot(*gap))
            if distance <= radius:
                candidates.append((distance, s))
        candidates.sort(key=lambda c: c[0])
        return [s for _, s in candidates[: p.loop_max_candidates]]

    def _surprising(self, off: np.ndarray) -> bool:
        """Whether a closure's offset ``off`` from the estimate (dx, dy, dθ in the node's frame)
        exceeds loop_agree_xy or loop_agree_theta: it would move the robot by more than two
        closures may disagree by."""
        p = self.params
        return math.hypot(off[0], off[1]) > p.loop_agree_xy or abs(off[2]) > p.loop_agree_theta

    def agrees(self, a: Closure, b: Closure) -> bool:
        """Whether two closures imply the same rigid correction: moved by each, the later node
        lands within loop_agree_xy, and the rotations differ by at most loop_agree_theta."""
        p = self.params
        node = self._graph.poses[b.node_id]
        gap = compose(a.correction, node)[:2] - compose(b.correction, node)[:2]
        turn = abs(float(wrap_angle(a.correction[2] - b.correction[2])))
        return math.hypot(gap[0], gap[1]) <= p.loop_agree_xy and turn <= p.loop_agree_theta

    def add(self, closure: Closure) -> None:
        """Add the closure to the graph; the drift since the last closure starts again at 0."""
        p = self.params
        self._graph.add_constraint(
            closure.submap_graph_id,
            closure.node_id,
            closure.pose,
            p.loop_sigma_xy,
            p.loop_sigma_theta,
        )
        self.closures += 1
        self.pending += 1
        self._drift_var_xy = 0.0
        self._drift_var_theta = 0.0
