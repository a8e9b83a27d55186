"""Correlative scan matching (Olson, "Real-time correlative scan matching", ICRA 2009).

The map is turned into a likelihood field F = exp(−d²/2σ²), d the distance to the nearest
occupied cell. A scan's score at a pose is the mean of F over its transformed points. The search
is exhaustive over a window (dx, dy, dθ) around a prior, done in two resolutions as in Olson §III-C:
a low-resolution field whose cell holds the maximum of F over the f×f high-resolution cells it
covers gives an upper bound for all f×f fine translations at once, so fine cells are only scored
under coarse cells whose bound beats the best fine score found so far (branch and bound).
Rotations are searched exhaustively at both levels; all candidates of a level are scored in one
vectorized gather. The covariance follows Olson §IV: the candidates' scores, turned into
probabilities, give the second moment around their mean. A few Gauss–Newton steps on the
bilinearly interpolated field then refine the discrete optimum to sub-cell accuracy (as the Ceres
step in Hess et al. 2016).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import distance_transform_edt

from agents.slam.occupancy import LogOddsGrid
from fleet.slam_params import SlamParams


def _window_max(a: np.ndarray, f: int) -> np.ndarray:
    """out[i, j] = max(a[i:i+f, j:j+f]), zero beyond the edge."""
    out = a.copy()
    for k in range(1, f):
        np.maximum(out[:-k], a[k:], out=out[:-k])
    rows = out.copy()
    for k in range(1, f):
        np.maximum(out[:, :-k], rows[:, k:], out=out[:, :-k])
    return out


def _sided(occupied: np.ndarray, free: np.ndarray, sectors: int) -> list[np.ndarray]:
    """Per beam direction k (grid-frame angle 2πk/``sectors``) the ``occupied`` cells such a
    beam can hit: those with a ``free`` cell within two steps on the sensor's side, along
    −u_k or 45° either side of it (8-neighbour steps). A face seen along its length still has
    free cells beside it on that side; a face two cells deep, or whose ray stopped a cell
    short, still has one two steps back; the far face of a wall 0.1 m thick has none."""
    rows, cols = occupied.shape
    reach = 2
    padded = np.zeros((rows + 2 * reach, cols + 2 * reach), dtype=bool)
    padded[reach:-reach, reach:-reach] = free
    layers = []
    for k in range(sectors):
        back = 2.0 * math.pi * k / sectors + math.pi
        near = np.zeros_like(occupied)
        for turn in (-0.25 * math.pi, 0.0, 0.25 * math.pi):
            dr, dc = round(math.sin(back + turn)), round(math.cos(back + turn))
            for step in range(1, reach + 1):
                r0, c0 = reach + step * dr, reach + step * dc
                near |= padded[r0 : r0 + rows, c0 : c0 + cols]
        layers.append(occupied & near)
    return layers


class LikelihoodField:
    """F = exp(−d²/2σ²) over a grid's occupied cells, with cached max-pooled levels.

    The outermost ring of cells is forced to zero, so lookups clipped into the array score
    points that fall outside the map as zero.

    With ``sectors`` K > 1 the field has one layer per direction a beam can travel in (sector
    k: within π/K of the grid-frame angle 2πk/K), stacked in ``values`` as K blocks of rows:
    layer k holds only the occupied cells that such a beam can hit, those with a known free
    cell within two steps on the sensor's side (toward −u_k or ±45° from it, ``_sided``). A
    wall's two faces are then told apart: a scan that sees a wall from one room does not fit
    a submap that saw only its other face from the next, one wall thickness away, which a
    field of distances alone scores almost as well as the face it sees (the likelihood field "sees
    through walls": it replaces ray casting by the nearest obstacle, Thrun et al.,
    Probabilistic Robotics §6.4). It weighs K times the memory of one layer (with its pooled
    level, about 2 MB for a finished submap of home's tour, 0.26 MB with one layer).
    """

    def __init__(self, grid: LogOddsGrid, sigma: float, sectors: int = 1) -> None:
        self.resolution = grid.resolution
        self.origin = grid.origin
        self.sectors = sectors
        rows, cols = grid.shape
        values = np.zeros((sectors, rows, cols), dtype=np.float32)
        if grid.touched is not None:
            pad = math.ceil(3.0 * sigma / grid.resolution) + 1
            r0, r1, c0, c1 = grid.touched
            r0, c0 = max(r0 - pad, 0), max(c0 - pad, 0)
            r1, c1 = min(r1 + pad, rows), min(c1 + pad, cols)
            block = grid.log_odds[r0:r1, c0:c1]
            occupied = block > 0
            layers = [occupied] if sectors == 1 else _sided(occupied, block < 0, sectors)
            for k, cells in enumerate(layers):
                if cells.any():
                    d = distance_transform_edt(~cells) * grid.resolution
                    values[k, r0:r1, c0:c1] = np.exp(-0.5 * (d / sigma) ** 2)
        values[:, 0, :] = values[:, -1, :] = 0.0
        values[:, :, 0] = values[:, :, -1] = 0.0
        self._shape = (rows, cols)
        self.values = values.reshape(sectors * rows, cols)
        self._pooled: dict[int, np.ndarray] = {1: self.values}

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) of one layer."""
        return self._shape

    def pooled(self, factor: int) -> np.ndarray:
        """The layers max-pooled over ``factor``² cells, stacked as ``values`` is."""
        if factor not in self._pooled:
            rows, cols = self._shape
            layers = self.values.reshape(self.sectors, rows, cols)
            pooled = np.concatenate([_window_max(layer, factor) for layer in layers])
            self._pooled[factor] = pooled
        return self._pooled[factor]

    def layers(self, angles: np.ndarray) -> np.ndarray | None:
        """The flat offset into ``values`` of the layer for beams travelling at ``angles``
        (grid frame, radians); None for a field of one layer."""
        if self.sectors == 1:
            return None
        k = np.rint(angles * (self.sectors / (2.0 * math.pi))).astype(np.int64) % self.sectors
        return k * (self._shape[0] * self._shape[1])

    def bilinear(
        self, x: np.ndarray, y: np.ndarray, layer: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """F and its gradient (dF/dx, dF/dy) at local points (in the layers ``layer``, flat
        offsets from ``layers``), interpolated between cell centres:
        F = f00 + a·fu + fv·(b + t·fu) with a = f01 − f00, b = f10 − f00, t = f11 − f10 − a."""
        rows, cols = self.shape
        scale = 1.0 / self.resolution
        u = (x - self.origin[0]) * scale - 0.5
        v = (y - self.origin[1]) * scale - 0.5
        np.minimum(np.maximum(u, 0.0, out=u), cols - 1.001, out=u)
        np.minimum(np.maximum(v, 0.0, out=v), rows - 1.001, out=v)
        j = u.astype(np.int64)  # u, v ≥ 0: truncation is the floor
        at = v.astype(np.int64)
        fu, fv = u - j, v - at
        at *= cols
        at += j
        if layer is not None:
            at += layer
        f = self.values.reshape(-1)
        f00, f01, f10, f11 = f[at], f[at + 1], f[at + cols], f[at + cols + 1]
        a = f01 - f00
        b = f10 - f00
        t = f11 - f10 - a
        value = f00 + fu * a + fv * (b + fu * t)
        return value, (a + fv * t) * scale, (b + fu * t) * scale


@dataclass(frozen=True)
class MatchResult:
    """The best pose in the field's frame, its mean likelihood in [0, 1], and its covariance.

    ``rival_gap`` is how much lower (in the search's score) the best *distinct* candidate
    scored: one more than ``distinct_xy`` away or turned more than ``distinct_theta`` from the
    best; ``inf`` when no distinct candidate was scored (see ``CorrelativeMatcher.match``).
    """

    pose: np.ndarray
    score: float
    covariance: np.ndarray
    rival_gap: float = math.inf


class CorrelativeMatcher:
    """Olson's multi-resolution correlative matcher with a Gaussian prior penalty and a
    Gauss–Newton refinement; tunables come from ``SlamParams``."""

    def __init__(self, params: SlamParams) -> None:
        self.params = params

    def match(
        self,
        field: LikelihoodField,
        points: np.ndarray,
        prior: np.ndarray,
        window_xy: float,
        window_theta: float,
        coarse_factor: int,
        penalize: bool = True,
        search_points: int | None = None,
        penalties: tuple[float, float] | None = None,
        max_coarse: int | None = None,
        distinct: tuple[float, float] | None = None,
        rival_margin: float = 0.0,
    ) -> MatchResult:
        """Match ``points`` (N, 2, sensor frame) against ``field`` around ``prior`` (field frame).

        With ``penalize`` the score is reduced with the squared distance from the prior (an
        odometry prior; ``penalties`` per m² and per rad² replace the parameters' own);
        loop-closure searches turn it off, their prior carries drift. With
        ``search_points`` the discrete search uses an evenly strided subset of that many points
        (and refines only the best coarse cells); the refinement and the score use all points.
        With ``max_coarse`` at most that many coarse cells (the highest bounds) are searched at
        the fine level: a search for a match that is not there (most loop-closure candidates)
        finds no bound to prune with and would otherwise score most of the window.
        With ``distinct`` = (metres, radians) the result's ``rival_gap`` is the best score minus
        that of the best candidate farther than that from it (a second mode: the scan slid along
        a straight wall, or onto the next step of a wall that the map drew as a staircase);
        every coarse cell whose bound is within ``rival_margin`` of the best is then scored, so a
        rival that close is not pruned (the uniqueness test of place recognition, e.g. Olson,
        "Recognizing places using spectrally clustered local matches", RAS 2009).
        """
        p = self.params
        if penalties is None:
            penalties = (p.translation_penalty, p.rotation_penalty)
        t_pen, r_pen = penalties if penalize else (0.0, 0.0)
        prior = np.asarray(prior, dtype=float)
        n_points = points.shape[0]
        searched = points
        margin = p.covariance_margin
        if search_points is not None and n_points > search_points:
            searched = points[:: math.ceil(n_points / search_points)]
            margin = 0.0
        if distinct is not None:
            margin = max(margin, rival_margin)
        window = _Window.around(
            field, searched, prior, window_xy, window_theta, p.angular_step, (t_pen, r_pen)
        )
        coarse, starts, f = _coarse_bounds(field, window, coarse_factor)
        cand = _branch_and_bound(field, window, coarse, starts, f, margin, max_coarse)
        top = cand[np.argmax(cand[:, 3])]
        covariance = self._covariance(cand, n_points, field.resolution)
        rival_gap = math.inf if distinct is None else _rival_gap(cand, top, distinct)
        pose, score = self._refine(field, points, prior + top[:3], prior, t_pen, r_pen)
        return MatchResult(pose=pose, score=score, covariance=covariance, rival_gap=rival_gap)

    def track(
        self,
        field: LikelihoodField,
        points: np.ndarray,
        prior: np.ndarray,
        penalties: tuple[float, float],
    ) -> tuple[np.ndarray, float] | None:
        """The Gauss–Newton refinement alone, from ``prior`` (no discrete search), as
        Cartographer's 2D tracking does by default (Hess et al. 2016: the Ceres scan matcher
        with the online correlative search off): the pose and its mean F, or None when the fit
        ends on its bound one search cell from the prior (the optimum lies farther: search)."""
        prior = np.asarray(prior, dtype=float)
        pose, score = self._refine(field, points, prior, prior, *penalties)
        bound = np.array([field.resolution, field.resolution, self.params.angular_step])
        if (np.abs(pose - prior) >= bound * (1 - 1e-6)).any():
            return None
        return pose, score

    def _covariance(self, cand: np.ndarray, n_points: int, res: float) -> np.ndarray:
        """Olson 2009 §IV: Σ = Σᵢ wᵢ xᵢxᵢᵀ / Σ w − μμᵀ with wᵢ from the candidate scores."""
        w = np.exp(self.params.score_information_gain * n_points * (cand[:, 3] - cand[:, 3].max()))
        x = cand[:, :3]
        mu = (w[:, None] * x).sum(axis=0) / w.sum()
        d = x - mu
        cov = (w[:, None, None] * d[:, :, None] * d[:, None, :]).sum(axis=0) / w.sum()
        floor = np.array([res * res, res * res, self.params.angular_step**2]) / 12.0
        return cov + np.diag(floor)

    def _refine(
        self,
        field: LikelihoodField,
        points: np.ndarray,
        start: np.ndarray,
        prior: np.ndarray,
        t_pen: float,
        r_pen: float,
    ) -> tuple[np.ndarray, float]:
        """Gauss–Newton on Σ(1 − F)/N + penalties (the search's own objective), kept within one
        search cell of ``start``; returns the pose and its mean F. The residuals are √(1 − F):
        near a wall 1 − F ≈ d²/2σ², so they grow linearly with the distance d and the fit pulls
        like point-to-wall ICP; residuals 1 − F would be flat (quartic cost) near the optimum and
        let the prior penalty win. The normal equations JᵀJ·δ = −Jᵀr are summed directly
        (3 × 3), not formed from the stacked residuals."""
        p = self.params
        n = points.shape[0]
        sx, sy = points[:, 0], points[:, 1]
        layer = field.layers(start[2] + np.arctan2(sy, sx))
        pen = np.array([t_pen, t_pen, r_pen])
        lo = start - np.array([field.resolution, field.resolution, p.angular_step])
        hi = start + np.array([field.resolution, field.resolution, p.angular_step])

        def linearize(pose: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
            """The cost at ``pose``, JᵀJ and Jᵀr."""
            c, s = math.cos(pose[2]), math.sin(pose[2])
            dx = c * sx - s * sy  # the points turned, before the translation
            dy = s * sx + c * sy
            value, gx, gy = field.bilinear(dx + pose[0], dy + pose[1], layer)
            miss2 = np.maximum(1.0 - value, 0.0)
            miss = np.sqrt(miss2)
            d_miss = -0.5 / np.maximum(miss, 1e-4)
            jac = np.empty((3, n))
            jac[0], jac[1], jac[2] = gx, gy, gx * -dy + gy * dx
            jac *= d_miss
            off = pose - prior
            h = (jac @ jac.T) / n
            h[np.diag_indices(3)] += pen + 1e-9
            grad = (jac @ miss) / n + pen * off
            return float(miss2.sum()) / n + float(pen @ (off * off)), h, grad

        pose = start.copy()
        cost, h, grad = linearize(pose)
        for _ in range(p.refine_iterations):
            step = np.linalg.solve(h, -grad)
            trial = np.minimum(np.maximum(pose + step, lo), hi)
            cost_new, h_new, grad_new = linearize(trial)
            if cost_new >= cost:
                break
            pose, cost, h, grad = trial, cost_new, h_new, grad_new
        off = pose - prior
        return pose, 1.0 - (cost - float(pen @ (off * off)))


@dataclass(frozen=True, eq=False)
class _Window:
    """A discrete search window around a prior: ± ``n_xy`` cells and the rotations ``d_theta``
    (offsets from the prior's heading), each point's cell at every rotation before translation,
    and the prior penalty of each rotation and of one cell² of translation."""

    n_xy: int
    d_theta: np.ndarray  # (T,)
    row0: np.ndarray  # (T, N)
    col0: np.ndarray  # (T, N)
    rot_penalty: np.ndarray  # (T,)
    pen_xy: float
    extent: tuple[int, int, int, int]  # the lowest and highest row, the lowest and highest col
    layer: np.ndarray | None  # (T, N) flat offsets of each point's layer (a sided field)

    def leaves(self, shape: tuple[int, int], f: int) -> bool:
        """Whether a point shifted by −n_xy … n_xy + f − 1 cells (every shift the two levels
        read) can leave a grid of ``shape``: only then are the cells clipped to its edge."""
        lo, hi = -self.n_xy, self.n_xy + f - 1
        r_min, r_max, c_min, c_max = self.extent
        return r_min + lo < 0 or c_min + lo < 0 or r_max + hi >= shape[0] or c_max + hi >= shape[1]

    @classmethod
    def around(
        cls,
        field: LikelihoodField,
        points: np.ndarray,
        prior: np.ndarray,
        window_xy: float,
        window_theta: float,
        angular_step: float,
        penalties: tuple[float, float],
    ) -> _Window:
        res = field.resolution
        t_pen, r_pen = penalties
        n_xy = math.ceil(window_xy / res - 1e-9)
        n_th = math.ceil(window_theta / angular_step - 1e-9)
        d_theta = np.arange(-n_th, n_th + 1) * angular_step
        c, s = np.cos(prior[2] + d_theta), np.sin(prior[2] + d_theta)
        px = c[:, None] * points[:, 0] - s[:, None] * points[:, 1] + prior[0]
        py = s[:, None] * points[:, 0] + c[:, None] * points[:, 1] + prior[1]
        col0 = np.floor((px - field.origin[0]) / res).astype(np.int64)
        row0 = np.floor((py - field.origin[1]) / res).astype(np.int64)
        extent = (int(row0.min()), int(row0.max()), int(col0.min()), int(col0.max()))
        layer = None
        if field.sectors > 1:
            bearing = np.arctan2(points[:, 1], points[:, 0])
            layer = field.layers(prior[2] + d_theta[:, None] + bearing)
        return cls(n_xy, d_theta, row0, col0, r_pen * d_theta**2, t_pen * res * res, extent, layer)


def _coarse_bounds(
    field: LikelihoodField, window: _Window, coarse_factor: int
) -> tuple[np.ndarray, np.ndarray, int]:
    """The low-resolution level of Olson 2009 §III-C: for every rotation and every block of
    f×f translations, the score on the max-pooled field minus the smallest prior penalty in the
    block, an upper bound of every fine score in it. Returns the bounds (T, Y, X), the first
    translation (cells) of each block along an axis, and f."""
    n_xy = window.n_xy
    f = max(1, min(coarse_factor, 2 * n_xy + 1))
    starts = np.arange(-n_xy, n_xy + 1, f)
    ends = np.minimum(starts + f - 1, n_xy)
    nearest = np.where((starts <= 0) & (ends >= 0), 0, np.minimum(abs(starts), abs(ends)))
    table = field.pooled(f)
    at = _cells(
        window.row0,
        window.col0,
        starts[None],
        starts[None],
        field.shape,
        window.leaves(field.shape, f),
        window.layer,
    )
    coarse = table.reshape(-1)[at].mean(axis=-1)
    coarse -= window.rot_penalty[:, None, None]
    coarse -= window.pen_xy * (nearest[None, :, None] ** 2 + nearest[None, None, :] ** 2)
    return coarse, starts, f


def _branch_and_bound(
    field: LikelihoodField,
    window: _Window,
    coarse: np.ndarray,
    starts: np.ndarray,
    f: int,
    margin: float,
    max_coarse: int | None,
) -> np.ndarray:
    """The full-resolution level of Olson 2009 §III-C: the fine translations under each coarse
    block, best bound first, until a bound falls ``margin`` below the best fine score (or after
    ``max_coarse`` blocks). Returns every scored candidate as rows (dx, dy, dθ, score)."""
    res = field.resolution
    n_xy = window.n_xy
    order = np.argsort(coarse, axis=None)[::-1]
    coarse_sorted = coarse.reshape(-1)[order]
    offs = np.arange(f)
    clip = window.leaves(field.shape, f)
    samples: list[np.ndarray] = []
    best = -np.inf
    k, batch = 0, 4
    limit = order.size if max_coarse is None else min(order.size, max_coarse)
    while k < limit:
        if coarse_sorted[k] < best - margin:
            break
        # Coarse cells in order of their bound, in batches that double (up to 64): the first
        # few set the best fine score, later ones are cut by it in few numpy calls.
        end = min(k + batch, limit)
        chunk = order[k:end]
        chunk = chunk[coarse_sorted[k:end] >= best - margin]
        k += batch
        batch = min(2 * batch, 64)
        ti, jy, jx = np.unravel_index(chunk, coarse.shape)
        ky = starts[jy][:, None] + offs  # (B, f)
        kx = starts[jx][:, None] + offs
        layer = None if window.layer is None else window.layer[ti]
        at = _cells(window.row0[ti], window.col0[ti], ky, kx, field.shape, clip, layer)
        score = field.values.reshape(-1)[at].mean(axis=-1)
        score -= window.rot_penalty[ti][:, None, None]
        score -= window.pen_xy * (ky[:, :, None] ** 2 + kx[:, None, :] ** 2)
        valid = (ky[:, :, None] <= n_xy) & (kx[:, None, :] <= n_xy)
        score = np.where(valid, score, -np.inf)
        best = max(best, float(score.max()))
        grid_t = np.broadcast_to(window.d_theta[ti][:, None, None], score.shape)
        grid_y = np.broadcast_to(ky[:, :, None] * res, score.shape)
        grid_x = np.broadcast_to(kx[:, None, :] * res, score.shape)
        samples.append(np.stack([grid_x, grid_y, grid_t, score], axis=-1).reshape(-1, 4))
    cand = np.concatenate(samples)
    return cand[np.isfinite(cand[:, 3])]


def _rival_gap(cand: np.ndarray, top: np.ndarray, distinct: tuple[float, float]) -> float:
    """The best candidate's score minus that of the best one farther than ``distinct``
    (metres, radians) from it; ``inf`` when there is none."""
    off = cand[:, :3] - top[:3]
    far = (np.hypot(off[:, 0], off[:, 1]) > distinct[0]) | (np.abs(off[:, 2]) > distinct[1])
    if not far.any():
        return math.inf
    return float(top[3] - cand[far, 3].max())


def _cells(
    row0: np.ndarray,
    col0: np.ndarray,
    dy: np.ndarray,
    dx: np.ndarray,
    shape: tuple[int, int],
    clip: bool,
    layer: np.ndarray | None = None,
) -> np.ndarray:
    """Flat indices (B, Y, X, N) of the cells (B, N) shifted by every (dy, dx) of their row
    ((B or 1, Y) and (B or 1, X) cells), clipped to the grid's edge with ``clip``, in the
    layers ``layer`` ((B, N) flat offsets) of a sided field."""
    rows, cols = shape
    r = row0[:, None, :] + dy[:, :, None]
    c = col0[:, None, :] + dx[:, :, None]
    if clip:
        np.clip(r, 0, rows - 1, out=r)
        np.clip(c, 0, cols - 1, out=c)
    r *= cols
    if layer is not None:
        c = c + layer[:, None, :]
    return r[:, :, None, :] + c[:, None, :, :]
