"""Whether the stored map a fleet cleans on is the floor its robots see.

A robot's SLAM map starts at its known start pose, so it is in the stored map's frame (the
world's) from the first scan. :func:`check_map` matches it against the stored map around that
frame (``planners.map_match.refine_transform``, Olson 2009) and reads the match's acceptance
test (Birk and Carpin 2006, as for merging): walls of either map that land on the other's
known floor pull the score down, cells unknown to either count for nothing. The robot's map
**agrees** when the match is confident and its frame lies within ``max_offset_m`` and
``max_offset_deg`` of the stored map's (a map of the same home drawn in another frame is as
wrong as another home's); it **differs** when the two overlap by ``min_overlap_m2`` of commonly
observed floor (where they lie, as they are) and yet the best placement near the frame scores
below ``min_score`` (or none puts a wall on a wall), or lies too far from it; else (too little
seen yet, or a place that looks alike from elsewhere) it is **undecided** and is asked again
once the robot has seen more.

:func:`fleet_verdict` refuses the map only when more than half of the fleet's robots say it
differs, so one robot whose own SLAM went wrong cannot stop a fleet on the right map.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from planners.checks import require_positive
from planners.grid import GridMap
from planners.map_match import MatchParams, refine_transform
from planners.map_merge import Transform2D

AGREES = "agrees"
DIFFERS = "differs"
UNDECIDED = "undecided"


@dataclass(frozen=True)
class MapCheckParams:
    """The matcher's parameters (its acceptance thresholds decide), and how far the robot's
    frame may lie from the stored map's for the two to agree."""

    match: MatchParams = field(default_factory=MatchParams)
    max_offset_m: float = 0.2
    max_offset_deg: float = 5.0

    def validate(self) -> None:
        self.match.validate()
        require_positive(self, "max_offset_m", "max_offset_deg")


@dataclass(frozen=True)
class MapCheck:
    """One robot's map against the stored map: the verdict (:data:`AGREES`, :data:`DIFFERS`,
    :data:`UNDECIDED`), the match's score, the floor both observed (m², :func:`common_m2`),
    where the robot's frame fits the stored map best, and why, in words."""

    verdict: str
    score: float
    overlap_m2: float
    offset: Transform2D
    reason: str


def check_map(seen: GridMap, stored: GridMap, params: MapCheckParams) -> MapCheck:
    """``seen`` (a robot's SLAM map, in the world's frame) against ``stored``."""
    params.validate()
    m = params.match
    common = common_m2(seen, stored)
    match = refine_transform(seen, stored, Transform2D.identity(), m)
    off = match.transform
    shift = math.hypot(off.x, off.y)
    turn = abs(math.degrees(off.theta))
    figures = f"score {match.score:.2f}, {common:.1f} m² seen by both"
    if common < m.min_overlap_m2:
        return MapCheck(UNDECIDED, match.score, common, off, f"too little seen: {figures}")
    if match.score < m.min_score:
        why = (
            f"its walls and the stored map's do not line up ({figures}; a score of at least "
            f"{m.min_score:.2f} needed)"
        )
        return MapCheck(DIFFERS, match.score, common, off, why)
    if shift > params.max_offset_m or turn > params.max_offset_deg:
        why = (
            f"it fits the stored map only moved by {shift:.2f} m and turned by {turn:.1f}° "
            f"({figures}; at most {params.max_offset_m:.2f} m and {params.max_offset_deg:.1f}°)"
        )
        return MapCheck(DIFFERS, match.score, common, off, why)
    if not match.confident:
        return MapCheck(UNDECIDED, match.score, common, off, match.reason)
    return MapCheck(AGREES, match.score, common, off, f"matches: {figures}")


def common_m2(seen: GridMap, stored: GridMap) -> float:
    """The floor (m²) both maps observed where they lie, frames as they are: ``seen``'s known
    cells whose centres fall on ``stored``'s known cells."""
    rc = stored.world_to_cell(seen.cell_to_world(np.argwhere(~seen.unknown)))
    rc = rc[stored.in_bounds(rc)]
    return float((~stored.unknown[rc[:, 0], rc[:, 1]]).sum()) * seen.resolution**2


def fleet_verdict(checks: Iterable[MapCheck], robots: int) -> str:
    """:data:`DIFFERS` once more than half of the ``robots`` robots' maps differ from the stored
    map, :data:`AGREES` once more than half agree, else :data:`UNDECIDED`."""
    verdicts = [c.verdict for c in checks]
    if 2 * verdicts.count(DIFFERS) > robots:
        return DIFFERS
    if 2 * verdicts.count(AGREES) > robots:
        return AGREES
    return UNDECIDED
