"""Where one robot's map lies in the common frame: correlative map matching.

The search follows Olson, "Real-time correlative scan matching" (ICRA 2009), with the moving
map's occupied cells as the "scan" and the reference map (the other robots' maps, merged) as
the map. The reference becomes a field

    G = F − w · free · (1 − F)²,   F = exp(−d² / 2σ²),

d the distance to its nearest occupied cell: walls attract the moving map's walls, the
reference's known-free floor repels them (weight w, ``free_penalty``; squared so a wall a cell
or a coarse cell off still scores above zero), its unknown cells are neutral. A pose's score
is the sum of G over the moving map's transformed occupied cells: Olson's log-likelihood of
the "scan", with a wall on known floor far less likely than one on the unknown.

1. Coarse, exhaustive (Olson §III-C's low-resolution level): for every rotation step, the moving
   map's rotated cells are counted into an image of ``coarse_factor``-times larger cells and
   cross-correlated with the coarse field by FFT, which scores every translation at once. Local
   maxima of each rotation's score image are the candidates.
2. The best candidates that are distinct from each other (more than ``distinct_xy`` or
   ``distinct_theta_deg`` apart) are searched again at full resolution, rotations
   ``fine_step_deg`` apart, in a window of one coarse cell and one coarse rotation step; all
   poses of a rotation are scored in one vectorized gather.
3. The best is refined continuously on the bilinearly interpolated field (Nelder–Mead; the
   Gauss–Newton step of Hess et al. 2016 on a smooth field plays the same part).

Confidence follows the acceptance test of Birk and Carpin, "Merging occupancy grid maps from
multiple robots" (Proc. IEEE 2006): a placement is taken only when the maps overlap by at least
``min_overlap_m2`` of commonly observed floor, both maps' walls that land on cells the other
map observed agree on average by at least ``min_score`` (each map's walls on the other's field,
so walls of either crossing the other's floor count), and no distinct runner-up that overlaps as
much scores more than ``max_ambiguity`` of the best (a symmetric or repetitive place, as
Olson's covariance estimate would show as a second mode).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import fft, ndimage, optimize

from planners.checks import require_positive
from planners.grid import GridMap
from planners.map_merge import LogOddsMap, Transform2D, affine_onto, merge_maps, wrap_angle


@dataclass(frozen=True)
class MatchParams:
    """How maps are matched. ``sigma`` (m) is the width of the wall likelihood field (as
    ``slam.match_sigma``); ``free_penalty`` weighs a wall landing on known floor. The coarse
    level uses cells ``coarse_factor`` times the map's and rotations ``coarse_step_deg`` apart,
    the fine level rotations ``fine_step_deg`` apart; at most ``max_points`` occupied cells of
    the moving map are matched (evenly thinned). A refinement searches ``window_xy`` (m) and
    ``window_theta_deg`` around its prior. ``candidates`` distinct coarse candidates are
    searched at full resolution. The acceptance thresholds are ``min_overlap_m2``,
    ``min_score`` and ``max_ambiguity``; ``occupied_threshold`` and ``free_threshold``
    (probabilities, as ``slam:``) read log-odds maps as occupied, free or unknown."""

    sigma: float = 0.075
    free_penalty: float = 3.0
    coarse_factor: int = 4
    coarse_step_deg: float = 2.0
    fine_step_deg: float = 0.5
    max_points: int = 4000
    window_xy: float = 0.6
    window_theta_deg: float = 10.0
    distinct_xy: float = 0.4
    distinct_theta_deg: float = 10.0
    candidates: int = 6
    min_overlap_m2: float = 4.0
    min_score: float = 0.3
    max_ambiguity: float = 0.8
    occupied_threshold: float = 0.65
    free_threshold: float = 0.35

    def validate(self) -> None:
        require_positive(
            self,
            "sigma",
            "coarse_factor",
            "coarse_step_deg",
            "fine_step_deg",
            "max_points",
            "window_xy",
            "window_theta_deg",
            "distinct_xy",
            "distinct_theta_deg",
            "candidates",
        )
        if self.free_penalty < 0 or self.min_overlap_m2 < 0:
            raise ValueError("free_penalty and min_overlap_m2 must be >= 0")
        if not 0.0 < self.max_ambiguity <= 1.0:
            raise ValueError("max_ambiguity must be within (0, 1]")
        if not 0.0 < self.free_threshold < self.occupied_threshold < 1.0:
            raise ValueError("need 0 < free_threshold < occupied_threshold < 1")


@dataclass(frozen=True)
class MapMatch:
    """Where the moving map lies: ``transform`` carries its frame into the reference's.

    ``score``: the mean field value over both maps' occupied cells that land on cells the other
    map observed (1: every wall on a wall; negative: walls on free floor). ``runner_up``: the best
    placement distinct from this one that overlaps the reference by ``min_overlap_m2`` too;
    ``ambiguity``: its score over this one's (0 without one; near 1: the place looks the same
    from both). ``overlap_m2``: floor observed in both maps. ``confident`` tells whether the
    match passed every acceptance test, ``reason`` says which one failed (or "matched")."""

    transform: Transform2D
    score: float
    ambiguity: float
    overlap_m2: float
    confident: bool
    reason: str
    runner_up: Transform2D | None


@dataclass(frozen=True, eq=False)
class _Field:
    """G over a grid (values (rows, cols), cell conventions of ``GridMap``)."""

    values: np.ndarray
    resolution: float
    origin: tuple[float, float]


@dataclass(frozen=True)
class _Candidate:
    """A pose in centred form: the moving map's centroid lands at (ux, uy), rotated by theta;
    ``total`` is its summed G."""

    ux: float
    uy: float
    theta: float
    total: float


def match_field(grid: GridMap, sigma: float, free_penalty: float) -> np.ndarray:
    """G = F − w·free·(1 − F)² of ``grid`` (see the module docstring)."""
    d = ndimage.distance_transform_edt(~grid.occupied) * grid.resolution
    f = np.exp(-0.5 * (d / sigma) ** 2)
    return (f - free_penalty * grid.free * (1.0 - f) ** 2).astype(np.float32)


def _coarse(grid: GridMap, factor: int) -> GridMap:
    """Blocks of ``factor``² cells: occupied if any cell is, unknown if every cell is."""
    rows, cols = grid.shape
    pr, pc = -rows % factor, -cols % factor
    occ = np.pad(grid.occupied, ((0, pr), (0, pc)))
    unk = np.pad(grid.unknown, ((0, pr), (0, pc)), constant_values=True)
    shape = (occ.shape[0] // factor, factor, occ.shape[1] // factor, factor)
    return GridMap(
        occ.reshape(shape).any(axis=(1, 3)),
        unk.reshape(shape).all(axis=(1, 3)) & ~occ.reshape(shape).any(axis=(1, 3)),
        grid.resolution * factor,
        grid.origin,
    )


def _points(grid: GridMap, max_points: int) -> np.ndarray:
    """World (x, y) of the occupied cells' centres, evenly thinned to at most ``max_points``."""
    rc = np.argwhere(grid.occupied)
    if len(rc) > max_points:
        rc = rc[np.linspace(0, len(rc) - 1, max_points).astype(int)]
    return grid.cell_to_world(rc)


def _rotate(points: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """(n, 2) points rotated by each of (k,) angles → (k, n, 2)."""
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    x, y = points[None, :, 0], points[None, :, 1]
    return np.stack([c * x - s * y, s * x + c * y], axis=-1)


def _coarse_candidates(
    centred: np.ndarray,
    field: _Field,
    thetas: np.ndarray,
    window: tuple[float, float, float] | None,
    params: MatchParams,
) -> list[_Candidate]:
    """Local maxima of the FFT cross-correlation of each rotation's point image with the coarse
    field, inside ``window`` ((ux, uy, half-width) of the centroid's landing place) if given."""
    res = field.resolution
    half = math.ceil(np.linalg.norm(centred, axis=1).max(initial=0.0) / res) + 1
    k = 2 * half
    rows, cols = field.values.shape
    size = (fft.next_fast_len(rows + k - 1), fft.next_fast_len(cols + k - 1))
    spectrum = fft.rfft2(field.values, size)
    # shift s (row, col) puts image cell (i, j) onto field cell (i + s_r, j + s_c); the image's
    # cell (0, 0) starts at (−half, −half)·res around the centroid
    shift_r = np.arange(rows + k - 1) - (k - 1)
    shift_c = np.arange(cols + k - 1) - (k - 1)
    uy = field.origin[1] + (shift_r + half) * res
    ux = field.origin[0] + (shift_c + half) * res
    inside = np.ones((len(uy), len(ux)), dtype=bool)
    if window is not None:
        wx, wy, w = window
        inside = (np.abs(uy - wy)[:, None] <= w + res) & (np.abs(ux - wx)[None, :] <= w + res)
    nms = 2 * math.ceil(params.distinct_xy / res) + 1
    found: list[_Candidate] = []
    for theta, pts in zip(thetas, _rotate(centred, thetas), strict=True):
        cells = np.floor(pts / res).astype(np.int64) + half
        image = np.bincount(cells[:, 1] * k + cells[:, 0], minlength=k * k).reshape(k, k)
        flipped = fft.rfft2(image[::-1, ::-1].astype(np.float32), size)
        corr = fft.irfft2(spectrum * flipped, size)[: rows + k - 1, : cols + k - 1]
        corr = np.where(inside, corr, -np.inf)
        peaks = (corr == ndimage.maximum_filter(corr, size=nms)) & (corr > 0)
        idx = np.flatnonzero(peaks)
        if idx.size == 0:
            continue
        top = idx[np.argsort(corr.flat[idx])[::-1][: params.candidates]]
        r, c = np.unravel_index(top, corr.shape)
        found.extend(
            _Candidate(float(ux[j]), float(uy[i]), float(theta), float(corr[i, j]))
            for i, j in zip(r, c, strict=True)
        )
    return sorted(found, key=lambda cand: -cand.total)


def _distinct(a: _Candidate, b: _Candidate, params: MatchParams) -> bool:
    return math.hypot(a.ux - b.ux, a.uy - b.uy) > params.distinct_xy or abs(
        wrap_angle(a.theta - b.theta)
    ) > math.radians(params.distinct_theta_deg)


def _pick_distinct(cands: Sequence[_Candidate], params: MatchParams) -> list[_Candidate]:
    picked: list[_Candidate] = []
    for cand in cands:
        if all(_distinct(cand, p, params) for p in picked):
            picked.append(cand)
            if len(picked) == params.candidates:
                break
    return picked


def _fine(
    centred: np.ndarray, field: _Field, start: _Candidate, coarse_res: float, params: MatchParams
) -> _Candidate:
    """Exhaustive search at full resolution: ± one coarse cell and ± one coarse rotation step
    around ``start``, every pose's sum of G (nearest cell) in one gather per rotation."""
    res = field.resolution
    n = math.ceil(coarse_res / res)
    steps = math.ceil(params.coarse_step_deg / params.fine_step_deg)
    thetas = start.theta + np.radians(params.fine_step_deg) * np.arange(-steps, steps + 1)
    offsets = np.arange(-n, n + 1) * res
    rows, cols = field.values.shape
    best = start
    best_total = -np.inf
    for theta, pts in zip(thetas, _rotate(centred, thetas), strict=True):
        col = np.floor((pts[:, 0] + start.ux - field.origin[0]) / res).astype(np.int64)
        row = np.floor((pts[:, 1] + start.uy - field.origin[1]) / res).astype(np.int64)
        rr = row[None, None, :] + np.arange(-n, n + 1)[:, None, None]
        cc = col[None, None, :] + np.arange(-n, n + 1)[None, :, None]
        ok = (rr >= 0) & (rr < rows) & (cc >= 0) & (cc < cols)
        vals = np.where(ok, field.values[np.clip(rr, 0, rows - 1), np.clip(cc, 0, cols - 1)], 0.0)
        totals = vals.sum(axis=2)
        i, j = np.unravel_index(int(np.argmax(totals)), totals.shape)
        if totals[i, j] > best_total:
            best_total = float(totals[i, j])
            best = _Candidate(
                start.ux + float(offsets[j]), start.uy + float(offsets[i]), float(theta), best_total
            )
    return best


def _bilinear_total(centred: np.ndarray, field: _Field, pose: np.ndarray) -> float:
    """Sum of G, bilinearly interpolated (cell centres at integer indices), at ``pose``."""
    pts = _rotate(centred, np.array([pose[2]]))[0] + pose[:2]
    col = (pts[:, 0] - field.origin[0]) / field.resolution - 0.5
    row = (pts[:, 1] - field.origin[1]) / field.resolution - 0.5
    return float(ndimage.map_coordinates(field.values, [row, col], order=1, cval=0.0).sum())


def _polish(
    centred: np.ndarray, field: _Field, start: _Candidate, params: MatchParams
) -> _Candidate:
    """Continuous refinement of ``start`` on the interpolated field (Nelder–Mead, a simplex of
    half a cell and half a fine rotation step), kept only when it scores higher."""
    x0 = np.array([start.ux, start.uy, start.theta])
    step = np.array(
        [field.resolution / 2, field.resolution / 2, math.radians(params.fine_step_deg) / 2]
    )
    simplex = np.vstack([x0, x0 + np.diag(step)])
    res = optimize.minimize(
        lambda p: -_bilinear_total(centred, field, p),
        x0,
        method="Nelder-Mead",
        options={"initial_simplex": simplex, "xatol": 1e-4, "fatol": 1e-3, "maxiter": 200},
    )
    if -res.fun < _bilinear_total(centred, field, x0):
        return start
    return _Candidate(float(res.x[0]), float(res.x[1]), float(res.x[2]), float(-res.fun))


def _to_transform(cand: _Candidate, centroid: np.ndarray) -> Transform2D:
    """Centred pose → the transform of the moving map's frame: p ↦ R(p − c) + u."""
    c, s = math.cos(cand.theta), math.sin(cand.theta)
    x = cand.ux - (c * centroid[0] - s * centroid[1])
    y = cand.uy - (s * centroid[0] + c * centroid[1])
    return Transform2D(float(x), float(y), wrap_angle(cand.theta))


def _overlap_m2(moving: GridMap, reference: GridMap, transform: Transform2D) -> float:
    seen = affine_onto(
        (~moving.unknown).astype(np.uint8),
        moving.resolution,
        moving.origin,
        transform,
        reference,
        order=0,
    )
    return float(((seen > 0) & ~reference.unknown).sum() * reference.resolution**2)


def _landing(points: np.ndarray, field: _Field, grid: GridMap) -> tuple[float, int]:
    """Sum of ``field`` over the ``points`` (world, ``grid``'s frame) that land on observed
    cells of ``grid``, and how many do."""
    rc = grid.world_to_cell(points)
    rc = rc[grid.in_bounds(rc)]
    rc = rc[~grid.unknown[rc[:, 0], rc[:, 1]]]
    return float(field.values[rc[:, 0], rc[:, 1]].sum()), len(rc)


@dataclass(frozen=True, eq=False)
class _Side:
    """One map's grid, field and (thinned) occupied cells, for the agreement test."""

    grid: GridMap
    field: _Field
    points: np.ndarray


def _agreement(moving: _Side, reference: _Side, transform: Transform2D) -> float:
    """Mean field value over both maps' walls that land on cells the other map observed: the
    moving map's on the reference's field and the reference's on the moving map's, so walls of
    either crossing the other's floor count (the two-way test of Birk and Carpin 2006)."""
    s1, n1 = _landing(transform.apply(moving.points), reference.field, reference.grid)
    s2, n2 = _landing(transform.inverse().apply(reference.points), moving.field, moving.grid)
    return (s1 + s2) / (n1 + n2) if n1 + n2 else 0.0


def _side(grid: GridMap, params: MatchParams) -> _Side:
    field = _Field(
        match_field(grid, params.sigma, params.free_penalty), grid.resolution, grid.origin
    )
    return _Side(grid, field, _points(grid, params.max_points))


def _search_space(
    prior: Transform2D | None, centroid: np.ndarray, params: MatchParams
) -> tuple[np.ndarray, tuple[float, float, float] | None]:
    """The coarse rotations, and the window (centre x, y and half-width) where the centroid may
    land: every rotation and anywhere without a prior, else the window around the prior."""
    step = math.radians(params.coarse_step_deg)
    if prior is None:
        return np.arange(-math.pi, math.pi, step), None
    n = math.ceil(params.window_theta_deg / params.coarse_step_deg)
    u = prior.apply(centroid)
    return prior.theta + step * np.arange(-n, n + 1), (float(u[0]), float(u[1]), params.window_xy)


def _verdict(
    score: float,
    overlap: float,
    ambiguity: float,
    runner_up: Transform2D | None,
    params: MatchParams,
) -> str:
    """ "matched", or the first acceptance test the match fails."""
    if score < params.min_score:
        return f"score {score:.2f} is below {params.min_score:.2f}"
    if overlap < params.min_overlap_m2:
        return f"overlap {overlap:.1f} m² is below {params.min_overlap_m2:.1f} m²"
    if runner_up is not None and ambiguity > params.max_ambiguity:
        return (
            f"ambiguous: a runner-up at ({runner_up.x:.2f}, {runner_up.y:.2f}, "
            f"{math.degrees(runner_up.theta):.0f}°) scores {ambiguity:.2f} of the best "
            f"(limit {params.max_ambiguity:.2f})"
        )
    return "matched"


def _match(
    moving: GridMap,
    reference: GridMap,
    prior: Transform2D | None,
    params: MatchParams,
) -> MapMatch:
    params.validate()
    fallback = prior or Transform2D.identity()
    moving_side = _side(moving, params)
    if len(moving_side.points) == 0 or not reference.occupied.any():
        return MapMatch(fallback, 0.0, 0.0, 0.0, False, "a map has no occupied cells", None)
    ref_side = _side(reference, params)
    centroid = moving_side.points.mean(axis=0)
    centred = moving_side.points - centroid
    coarse = _coarse(reference, params.coarse_factor)
    coarse_field = _Field(
        match_field(coarse, max(params.sigma, coarse.resolution), params.free_penalty),
        coarse.resolution,
        coarse.origin,
    )
    thetas, window = _search_space(prior, centroid, params)
    coarse_cands = _coarse_candidates(centred, coarse_field, thetas, window, params)
    if not coarse_cands:
        return MapMatch(fallback, 0.0, 0.0, 0.0, False, "no placement puts a wall on a wall", None)
    fine = [
        _fine(centred, ref_side.field, c, coarse.resolution, params)
        for c in _pick_distinct(coarse_cands, params)
    ]
    fine.sort(key=lambda cand: -cand.total)
    best = fine[0]
    transform = _to_transform(_polish(centred, ref_side.field, best, params), centroid)
    score = _agreement(moving_side, ref_side, transform)
    overlap = _overlap_m2(moving, reference, transform)
    runner_up, ambiguity = None, 0.0
    for cand in fine[1:]:
        other = _to_transform(cand, centroid)
        if _distinct(cand, best, params) and (
            _overlap_m2(moving, reference, other) >= params.min_overlap_m2
        ):
            runner_up = other
            rival_score = _agreement(moving_side, ref_side, other)
            ambiguity = max(rival_score, 0.0) / score if score > 0 else 1.0
            break
    reason = _verdict(score, overlap, ambiguity, runner_up, params)
    return MapMatch(transform, score, ambiguity, overlap, reason == "matched", reason, runner_up)


def refine_transform(
    moving: GridMap, reference: GridMap, prior: Transform2D, params: MatchParams
) -> MapMatch:
    """Correct ``prior`` (the moving map's frame → the reference's frame) by matching within
    ``params.window_xy`` and ``params.window_theta_deg`` of it."""
    return _match(moving, reference, prior, params)


def place_map(moving: GridMap, reference: GridMap, params: MatchParams) -> MapMatch:
    """Place a map whose start is unknown: a search over every rotation and every translation
    that overlaps the reference. Not ``confident`` (with the reason) unless the match is clear."""
    return _match(moving, reference, None, params)


def refine_transforms(
    maps: Sequence[LogOddsMap],
    priors: Sequence[Transform2D],
    limits: tuple[float, float],
    params: MatchParams,
    anchor: int = 0,
) -> tuple[MapMatch, ...]:
    """Refine each map's transform (but the ``anchor``'s, which fixes the common frame), in
    order, against the merge of the anchor and the maps confidently refined before it, so a map
    still off by its prior's error never pulls another. A map whose match is not confident keeps
    its prior and is left out of the later references. ``limits`` clamp the merged log-odds.
    The anchor's entry is its prior, unmeasured (score and overlap 0)."""
    placed = [anchor]
    current = list(priors)
    out: list[MapMatch] = []
    for i, m in enumerate(maps):
        if i == anchor:
            out.append(MapMatch(current[i], 0.0, 0.0, 0.0, True, "anchor: fixes the frame", None))
            continue
        reference = merge_maps([maps[j] for j in placed], [current[j] for j in placed], limits)
        match = refine_transform(
            m.to_gridmap(params.occupied_threshold, params.free_threshold),
            reference.to_gridmap(params.occupied_threshold, params.free_threshold),
            current[i],
            params,
        )
        if match.confident:
            current[i] = match.transform
            placed.append(i)
        out.append(match)
    return tuple(out)
