"""SLAM tunables: the ``slam:`` section of ``configs/fleet.yaml``. They live in the spine,
beside the other sections (fleet.params), so loading the parameters needs no robot software."""

from __future__ import annotations

import math
from dataclasses import dataclass

from planners.checks import require_non_negative, require_positive


@dataclass(frozen=True)
class SlamParams:
    """Parameters of the grid, the correlative matcher, submaps and the pose graph.

    Units are metres, radians and seconds. Probabilities are per-observation occupancy
    probabilities turned into log-odds increments (Thrun et al., Probabilistic Robotics §9.2).
    """

    # Occupancy grid
    resolution: float = 0.05
    max_range: float = 8.0  # beams longer than this (or than the sensor's range_max) are skipped
    # ... for their hits; the free space along a beam with no return is inserted this far (0:
    # none; at most the range)
    missing_ray_length: float = 3.0
    p_hit: float = 0.7
    p_miss: float = 0.4
    p_min: float = 0.12  # clamp, so a cell can change its mind after a few scans
    p_max: float = 0.97
    occupied_threshold: float = 0.65  # GridMap view: p ≥ this is occupied
    free_threshold: float = 0.35  # p ≤ this is free, in between is unknown
    map_tile: int = 32  # cells; the map's bounds snap to tiles and patches are whole tiles
    patch_tolerance: int = 5  # percent; smaller changes of a cell do not re-send its tile

    # Nodes (scans kept in the pose graph) and submaps (Hess et al. 2016)
    node_min_distance: float = 0.1  # a scan becomes a node after this much motion ...
    node_min_rotation: float = 0.1  # ... or this much rotation ...
    node_max_interval: float = 2.0  # ... or this much time
    submap_nodes: int = 40  # nodes per submap; a new one starts every submap_nodes/2
    submap_travel: float = 3.0  # or when the robot is this far from the newest submap's origin
    field_refresh_nodes: int = 4  # recompute the matching submap's likelihood field this often

    # Correlative scan matcher (Olson 2009), tracking
    match_sigma: float = 0.075  # Gaussian width of the likelihood field around occupied cells
    # the search's half-widths: search_window_sigmas σ of the step's odometry error (the
    # motion model below), at least search_window_min_xy/_theta, at most search_window_xy/_theta
    search_window_xy: float = 0.2
    search_window_theta: float = 0.2
    search_window_sigmas: float = 4.0
    search_window_min_xy: float = 0.1
    search_window_min_theta: float = 0.1
    angular_step: float = 0.008  # ≈ resolution / typical range: a far point moves ≤ one cell
    coarse_factor: int = 4  # low-resolution level = max-pool over coarse_factor² cells
    translation_penalty: float = 20.0  # score penalty per m² away from the odometry prior ...
    rotation_penalty: float = 40.0  # ... per rad²; at most these, and at most prior_weight / σ²
    # Odometry motion model of one step (dd metres, dθ radians): σ_xy = a·dd + b per axis,
    # σ_θ = c·|dθ| + d·dd; a long or turning step then gets a weaker prior (see prior_weight).
    motion_xy_per_m: float = 0.05
    motion_xy_floor: float = 0.002
    motion_theta_per_rad: float = 0.05
    motion_theta_per_m: float = 0.02
    prior_weight: float = 0.005  # penalty per m² = min(translation_penalty, this / σ_xy²)
    min_match_score: float = 0.35  # below this mean likelihood, trust odometry instead
    refine_iterations: int = 6  # Gauss–Newton steps on the interpolated field after the search
    score_information_gain: float = 0.1  # Olson §IV weights exp(gain·N·(score − best))
    covariance_margin: float = 0.02  # also refine coarse cells this close to the best
    # Tracking between searches: the refinement alone from the odometry prior (Hess et al.
    # 2016), the search run every this many scans, and whenever the fit ends on its one-cell
    # bound or scores this much below the last matched scan (1: search every scan) ...
    track_search_every: int = 10
    track_score_drop: float = 0.02
    # ... or the step's odometry error (search_window_sigmas σ) may exceed these (m, rad)
    track_prior_xy: float = 0.05
    track_prior_theta: float = 0.025

    # Loop closure: scan-to-submap matching against older submaps
    loop_every_nodes: int = 5
    loop_search_radius: float = 3.0
    loop_window_xy: float = 0.8
    loop_window_theta: float = 0.35
    loop_coarse_factor: int = 8
    # A finished submap's likelihood field has this many layers, one per sector of beam
    # directions, each holding the wall faces a beam travelling that way can hit (the faces
    # with free space on its side): a scan of a wall's far face, from the next room, does not
    # close a loop one wall thickness off (agents.slam.matcher.LikelihoodField; 1: one layer,
    # faces not told apart)
    loop_field_sectors: int = 8
    loop_min_score: float = 0.6
    # A closure that moves the estimate by more than loop_agree_xy / _theta is kept only if
    # every candidate beyond those of the best scores at least this much lower: a scan that
    # fits two places of a submap (slid along a staircase or straight wall) closes no loop.
    loop_ambiguity_margin: float = 0.1
    loop_min_submap_gap: int = 2  # never close against the newest few submaps
    loop_max_candidates: int = 2
    loop_search_points: int = 90  # the loop-closure search scores this many evenly spaced points
    loop_max_coarse: int = 48  # the search refines at most this many coarse cells (time bound)
    # The window grows with the odometry uncertainty accumulated since the last closure
    # (loop_window_sigmas standard deviations, at least loop_window_xy/_theta, at most these):
    loop_window_sigmas: float = 3.0
    loop_window_max_xy: float = 2.0
    loop_window_max_theta: float = 0.5
    # A closure found beyond loop_window_xy/_theta of the estimate is only kept once a second
    # one, within loop_confirm_nodes nodes, implies the same correction (within these):
    loop_agree_xy: float = 0.3
    loop_agree_theta: float = 0.05
    loop_confirm_nodes: int = 25

    # Pose graph (sparse least squares)
    constraint_sigma_xy: float = 0.02
    constraint_sigma_theta: float = 0.01
    odom_sigma_xy: float = 0.05
    odom_sigma_theta: float = 0.03
    loop_sigma_xy: float = 0.05
    loop_sigma_theta: float = 0.02
    huber_scale: float = 1.0  # in standard deviations: a wrong loop closure is down-weighted
    optimize_every_nodes: int = 20  # optimize at most this often, and only after new closures
    # Optimize the newest this many poses only, the older held (0: all): bounded memory and
    # time per optimization on long runs; a home job adds about 1000-2000 per robot.
    optimize_window_nodes: int = 2000
    # A finished submap is dropped, its log-odds folded into older kept submaps, when they hold
    # at least this share of its wall cells as walls: the robot re-mapped known floor.
    trim_overlap: float = 0.9

    # Relocalization of a restarted agent in its saved map (agents/slam/relocalize.py)
    reloc_window_xy: float = 1.0  # search ± this around the saved pose: the body may have coasted
    reloc_window_theta: float = math.pi  # ± this; π searches every heading
    reloc_angular_step: float = 0.02  # rotation step of the wide search (then refined finer)
    reloc_coarse_factor: int = 8  # low-resolution level of the wide search's branch and bound
    reloc_search_points: int = 90  # the wide search scores this many evenly spaced points
    reloc_sectors: int = 8  # the heading window is searched in this many sectors, each's best kept
    reloc_min_points: int = 30  # fewer returns than this: do not try
    reloc_min_score: float = 0.6  # accept only a mean likelihood of at least this ...
    reloc_ambiguity_margin: float = 0.1  # ... and every distinct candidate this much lower
    reloc_distinct_xy: float = 0.3  # a candidate this far from the best (m) ...
    reloc_distinct_theta: float = 0.3  # ... or turned this much (rad) is a distinct hypothesis
    reloc_max_scans: int = 20  # a restarted agent gives up after this many scans without a match

    def validate(self) -> None:
        require_positive(
            self,
            "resolution",
            "max_range",
            "node_max_interval",
            "submap_travel",
            "match_sigma",
            "search_window_xy",
            "search_window_theta",
            "search_window_sigmas",
            "search_window_min_xy",
            "search_window_min_theta",
            "angular_step",
            "loop_search_radius",
            "loop_window_xy",
            "loop_window_theta",
            "constraint_sigma_xy",
            "constraint_sigma_theta",
            "odom_sigma_xy",
            "odom_sigma_theta",
            "loop_sigma_xy",
            "loop_sigma_theta",
            "huber_scale",
            "loop_window_sigmas",
            "loop_window_max_xy",
            "loop_window_max_theta",
            "loop_agree_xy",
            "loop_agree_theta",
            "motion_xy_floor",
            "prior_weight",
            "reloc_window_xy",
            "reloc_window_theta",
            "reloc_angular_step",
            "reloc_ambiguity_margin",
            "loop_ambiguity_margin",
            "reloc_distinct_xy",
            "reloc_distinct_theta",
        )
        require_non_negative(
            self,
            "missing_ray_length",
            "motion_xy_per_m",
            "motion_theta_per_rad",
            "motion_theta_per_m",
            "track_score_drop",
            "track_prior_xy",
            "track_prior_theta",
        )
        if not 0 < self.p_min < self.p_miss < 0.5 < self.p_hit < self.p_max < 1:
            raise ValueError("need 0 < p_min < p_miss < 0.5 < p_hit < p_max < 1")
        if not self.p_min < self.free_threshold < self.occupied_threshold < self.p_max:
            raise ValueError("need p_min < free_threshold < occupied_threshold < p_max")
        if not 0 <= self.patch_tolerance <= 100:
            raise ValueError("patch_tolerance must be within 0..100")
        if self.submap_nodes < 2:
            raise ValueError("submap_nodes must be >= 2")
        if self.optimize_window_nodes < 0:
            raise ValueError(
                "optimize_window_nodes must be >= 0 (0: the whole graph), "
                f"got {self.optimize_window_nodes}"
            )
        if not 0 < self.trim_overlap <= 1:
            raise ValueError(f"trim_overlap must be within (0, 1], got {self.trim_overlap}")
        require_positive(
            self,
            "coarse_factor",
            "loop_coarse_factor",
            "loop_field_sectors",
            "reloc_coarse_factor",
            "map_tile",
            "loop_search_points",
            "loop_max_coarse",
            "loop_confirm_nodes",
            "field_refresh_nodes",
            "loop_every_nodes",
            "optimize_every_nodes",
            "reloc_search_points",
            "reloc_sectors",
            "reloc_min_points",
            "reloc_max_scans",
            "track_search_every",
        )
        if self.search_window_theta > math.pi or self.loop_window_theta > math.pi:
            raise ValueError("angular search windows must be <= pi")
        if (
            self.search_window_min_xy > self.search_window_xy
            or self.search_window_min_theta > self.search_window_theta
        ):
            raise ValueError(
                "search_window_min_xy and search_window_min_theta must be <= search_window_xy "
                "and search_window_theta (the tracking window's floor above its cap)"
            )
        if not 0 < self.min_match_score < 1 or not 0 < self.loop_min_score < 1:
            raise ValueError("min_match_score and loop_min_score must be within (0, 1)")
        if self.reloc_window_theta > math.pi:
            raise ValueError("reloc_window_theta must be <= pi")
        if not 0 < self.reloc_min_score < 1:
            raise ValueError("reloc_min_score must be within (0, 1)")
        if self.reloc_ambiguity_margin >= self.reloc_min_score:
            raise ValueError("reloc_ambiguity_margin must be < reloc_min_score")
