"""Relocalization of a restarted robot in its saved map: one scan, a wide correlative search.

The saved ``SlamMap`` becomes a likelihood field as in tracking, and the correlative matcher
(Olson, ICRA 2009: multi-resolution branch and bound, no prior penalty, a strided subset of the
points) searches a window around the saved pose: ± ``window_xy`` and ± ``window_theta`` (up to
every heading), at the coarser rotation step ``reloc_angular_step``. A final matcher run with the
tracking parameters over ± one cell and ± one wide step, with every point and Gauss–Newton,
refines the winner (as the Ceres step in Hess et al., ICRA 2016).

Acceptance rule. The heading window is split into ``reloc_sectors`` equal sectors and each is
searched on its own, so each yields its own best pose ("candidate"). A candidate is *distinct*
from the best one when it lies more than ``reloc_distinct_xy`` away or is turned more than
``reloc_distinct_theta``. The match is accepted only if

* the best candidate's score (mean likelihood of all points) is at least ``reloc_min_score``, and
* every distinct candidate scores at least ``reloc_ambiguity_margin`` lower.

A room that looks the same turned by half a turn (or a quarter) yields two candidates of about
the same score in sectors that far apart, and is refused instead of being matched to the mirror
pose. An ambiguity at the same heading within one sector (a shift along a featureless corridor)
is not tested: the matcher returns one pose per sector.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from agents.slam.geometry import scan_to_points, wrap_angle
from agents.slam.matcher import CorrelativeMatcher, LikelihoodField
from agents.slam.occupancy import LogOddsGrid
from agents.slam.slam_map import SlamMap
from fleet.slam_params import SlamParams

Pose = tuple[float, float, float]


@dataclass(frozen=True)
class Relocalization:
    """The outcome: ``ok`` with the pose in the saved map's frame and its score, or not ``ok``
    with the ``reason`` (``pose`` is then the best guess, not to be used)."""

    ok: bool
    pose: Pose
    score: float
    reason: str


def map_grid(saved: SlamMap, params: SlamParams) -> LogOddsGrid:
    """The saved map as the ``LogOddsGrid`` a ``LikelihoodField`` is built from, padded with
    unobserved cells so walls on the map's edge keep their field (the field zeroes its outer
    ring) and ``touched`` set to the observed cells' bounds."""
    pad = math.ceil(3.0 * params.match_sigma / saved.resolution) + 2
    rows, cols = saved.shape
    grid = LogOddsGrid(
        (rows + 2 * pad, cols + 2 * pad),
        (saved.origin[0] - pad * saved.resolution, saved.origin[1] - pad * saved.resolution),
        saved.resolution,
        params.p_hit,
        params.p_miss,
        params.p_min,
        params.p_max,
    )
    grid.log_odds[pad : pad + rows, pad : pad + cols] = saved.log_odds
    seen_rows = np.flatnonzero((saved.log_odds != 0).any(axis=1))
    seen_cols = np.flatnonzero((saved.log_odds != 0).any(axis=0))
    if seen_rows.size:
        grid.touched = (
            int(seen_rows[0]) + pad,
            int(seen_rows[-1]) + pad + 1,
            int(seen_cols[0]) + pad,
            int(seen_cols[-1]) + pad + 1,
        )
    return grid


def map_field(saved: SlamMap, params: SlamParams) -> LikelihoodField:
    """The likelihood field of the saved map (Olson 2009), as tracking builds one per submap."""
    return LikelihoodField(map_grid(saved, params), params.match_sigma)


def relocalize(
    saved: SlamMap,
    params: SlamParams,
    ranges: np.ndarray,
    angle_min: float,
    angle_increment: float,
    prior: Pose,
    window_xy: float,
    window_theta: float,
    range_min: float,
    range_max: float,
    field: LikelihoodField | None = None,
) -> Relocalization:
    """Find the pose of one scan in ``saved`` within the window around ``prior`` (the saved
    pose), by the rule in the module docstring. ``field`` is ``map_field(saved, params)`` when
    the caller keeps it across attempts."""
    prior_arr = np.asarray(prior, dtype=float)
    points = scan_to_points(
        ranges, angle_min, angle_increment, range_min, min(range_max, params.max_range)
    )
    if points.shape[0] < params.reloc_min_points:
        return Relocalization(
            False,
            prior,
            0.0,
            f"{points.shape[0]} returns, fewer than reloc_min_points {params.reloc_min_points}",
        )
    if field is None:
        field = map_field(saved, params)
    scores, poses = _sector_bests(field, points, prior_arr, window_xy, window_theta, params)
    best = int(np.argmax(scores))
    fine = CorrelativeMatcher(params).match(
        field,
        points,
        poses[best],
        params.resolution,
        params.reloc_angular_step,
        params.coarse_factor,
        penalize=False,
    )
    found = (float(fine.pose[0]), float(fine.pose[1]), float(wrap_angle(fine.pose[2])))
    if fine.score < params.reloc_min_score:
        return Relocalization(
            False,
            found,
            fine.score,
            f"best score {fine.score:.3f} below reloc_min_score {params.reloc_min_score}",
        )
    ambiguity = _ambiguity(scores, poses, best, params)
    return Relocalization(not ambiguity, found, fine.score, ambiguity)


def _sector_bests(
    field: LikelihoodField,
    points: np.ndarray,
    prior: np.ndarray,
    window_xy: float,
    window_theta: float,
    params: SlamParams,
) -> tuple[np.ndarray, np.ndarray]:
    """The wide search: the best score and pose of each of the ``reloc_sectors`` heading
    sectors of ± ``window_theta`` around ``prior``, each searched over ± ``window_xy``."""
    wide = CorrelativeMatcher(dataclasses.replace(params, angular_step=params.reloc_angular_step))
    sectors = params.reloc_sectors
    half = window_theta / sectors
    candidates = []
    for k in range(sectors):
        centre = prior[2] - window_theta + (2 * k + 1) * half
        result = wide.match(
            field,
            points,
            np.array([prior[0], prior[1], centre]),
            window_xy,
            half,
            params.reloc_coarse_factor,
            penalize=False,
            search_points=params.reloc_search_points,
        )
        candidates.append((result.score, result.pose))
    return np.array([c[0] for c in candidates]), np.array([c[1] for c in candidates])


def _ambiguity(scores: np.ndarray, poses: np.ndarray, best: int, params: SlamParams) -> str:
    """Why the sector candidates are ambiguous: the best distinct one scores within
    ``reloc_ambiguity_margin`` of candidate ``best``; "" when none does."""
    offset = poses - poses[best]
    distinct = (np.hypot(offset[:, 0], offset[:, 1]) > params.reloc_distinct_xy) | (
        np.abs(wrap_angle(offset[:, 2])) > params.reloc_distinct_theta
    )
    rivals = np.flatnonzero(distinct & (scores > scores[best] - params.reloc_ambiguity_margin))
    if not rivals.size:
        return ""
    r = int(rivals[np.argmax(scores[rivals])])
    x, y, theta = poses[r]
    return (
        f"ambiguous: ({x:.2f}, {y:.2f}, {theta:.2f}) scores {scores[r]:.3f} against "
        f"{scores[best]:.3f}, within reloc_ambiguity_margin {params.reloc_ambiguity_margin}"
    )
