"""A 2D pose graph optimized by sparse nonlinear least squares (Gauss–Newton, sparse solve).

Every constraint says "pose b seen from pose a is z": residual r = (a⁻¹ ⊕ b) ⊖ z, whitened by
its standard deviations (the SPA formulation of Konolige et al. 2010, as used for submaps and
scan nodes in Hess et al. 2016). A Huber loss bounds the pull of a wrong loop closure. The
Jacobian is analytic and sparse: each constraint touches six variables.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from agents.slam.geometry import wrap_angle


@dataclass(frozen=True)
class OptimizationReport:
    """Gauss–Newton iterations used and the Huber cost of the whitened residuals before and
    after."""

    iterations: int
    initial_cost: float
    final_cost: float


class PoseGraph:
    """Poses (x, y, θ) and relative-pose constraints; pose 0 is held fixed (the gauge)."""

    def __init__(self) -> None:
        self._poses = np.zeros((0, 3))
        # one row per constraint: a, b, z (3), weights 1/σ (3); grown by doubling, so a
        # constraint costs 64 bytes, not a list entry and two small arrays each
        self._rows = np.zeros((64, 8))
        self._m = 0

    @property
    def poses(self) -> np.ndarray:
        return self._poses

    @property
    def num_constraints(self) -> int:
        return self._m

    def add_pose(self, pose: np.ndarray) -> int:
        self._poses = np.vstack([self._poses, np.asarray(pose, dtype=float)[None, :]])
        return self._poses.shape[0] - 1

    def set_pose(self, index: int, pose: np.ndarray) -> None:
        self._poses[index] = pose

    def add_constraint(
        self, a: int, b: int, z: np.ndarray, sigma_xy: float, sigma_theta: float
    ) -> None:
        if self._m == len(self._rows):
            self._rows = np.vstack([self._rows, np.zeros_like(self._rows)])
        z = np.asarray(z, dtype=float)
        self._rows[self._m] = (a, b, z[0], z[1], z[2], 1 / sigma_xy, 1 / sigma_xy, 1 / sigma_theta)
        self._m += 1

    def optimize(
        self, huber_scale: float, max_iterations: int = 5, tolerance: float = 1e-4
    ) -> OptimizationReport:
        """Minimize the whitened residuals with a Huber loss (scale in standard deviations) by
        Gauss–Newton with iteratively reweighted least squares, from the current poses (the
        previous solution: incremental use needs few iterations). Each step solves the sparse
        normal equations JᵀWJ·δ = −JᵀWr (SuperLU with a COLAMD ordering); it stops when no
        variable moves by ``tolerance`` or after ``max_iterations``."""
        if not self._m:
            return OptimizationReport(0, 0.0, 0.0)
        rows = self._rows[: self._m]
        a = rows[:, 0].astype(np.int64)
        b = rows[:, 1].astype(np.int64)
        z = rows[:, 2:5]
        w = rows[:, 5:8]
        n = self._poses.shape[0]
        m = a.size
        anchor = self._poses[0].copy()
        anchor_w = 1e4

        def residuals(flat: np.ndarray) -> np.ndarray:
            x = flat.reshape(n, 3)
            pa, pb = x[a], x[b]
            c, s = np.cos(pa[:, 2]), np.sin(pa[:, 2])
            dx, dy = pb[:, 0] - pa[:, 0], pb[:, 1] - pa[:, 1]
            r = np.empty((m, 3))
            r[:, 0] = c * dx + s * dy - z[:, 0]
            r[:, 1] = -s * dx + c * dy - z[:, 1]
            r[:, 2] = wrap_angle(pb[:, 2] - pa[:, 2] - z[:, 2])
            r *= w
            return np.concatenate([r.reshape(-1), anchor_w * (x[0] - anchor)])

        rows3 = 3 * np.arange(m)
        row_idx = np.concatenate(
            [
                np.repeat(rows3, 5),
                np.repeat(rows3 + 1, 5),
                np.repeat(rows3 + 2, 2),
                3 * m + np.arange(3),
            ]
        )
        cols_xy = np.stack([3 * a, 3 * a + 1, 3 * a + 2, 3 * b, 3 * b + 1], axis=1).reshape(-1)
        cols_t = np.stack([3 * a + 2, 3 * b + 2], axis=1).reshape(-1)
        col_idx = np.concatenate([cols_xy, cols_xy, cols_t, np.arange(3)])

        def jacobian(flat: np.ndarray) -> sp.csr_matrix:
            x = flat.reshape(n, 3)
            pa, pb = x[a], x[b]
            c, s = np.cos(pa[:, 2]), np.sin(pa[:, 2])
            dx, dy = pb[:, 0] - pa[:, 0], pb[:, 1] - pa[:, 1]
            jx = np.stack([-c, -s, -s * dx + c * dy, c, s], axis=1) * w[:, :1]
            jy = np.stack([s, -c, -c * dx - s * dy, -s, c], axis=1) * w[:, 1:2]
            jt = np.stack([-np.ones(m), np.ones(m)], axis=1) * w[:, 2:3]
            data = np.concatenate(
                [jx.reshape(-1), jy.reshape(-1), jt.reshape(-1), np.full(3, anchor_w)]
            )
            return sp.csr_matrix((data, (row_idx, col_idx)), shape=(3 * m + 3, 3 * n))

        # A tiny Levenberg damping keeps poses that no constraint touches yet (a submap just
        # started) from making the normal equations singular; it moves nothing else.
        damping = sp.identity(3 * n, format="csr") * 1e-9
        x = self._poses.reshape(-1).copy()
        initial = final = _huber_cost(residuals(x), m, huber_scale)
        iterations = 0
        while iterations < max_iterations:
            iterations += 1
            r = residuals(x)
            jac = jacobian(x)
            weights = _huber_weights(r, m, huber_scale)
            jw = sp.diags(weights) @ jac
            h = (jac.T @ jw + damping).tocsc()
            step = spsolve(h, -(jw.T @ r))
            x += step
            final = _huber_cost(residuals(x), m, huber_scale)
            if np.max(np.abs(step)) < tolerance:
                break
        x = x.reshape(n, 3)
        x[:, 2] = wrap_angle(x[:, 2])
        self._poses = x
        return OptimizationReport(iterations, initial, final)


def _huber_weights(r: np.ndarray, m: int, scale: float) -> np.ndarray:
    """Iteratively reweighted least squares weights of the Huber loss, one per constraint:
    1 where its whitened 3-vector residual e is within ``scale``, scale/‖e‖ beyond (the anchor
    rows keep weight 1)."""
    norms = np.linalg.norm(r[: 3 * m].reshape(m, 3), axis=1)
    per = np.where(norms <= scale, 1.0, scale / np.maximum(norms, 1e-12))
    return np.concatenate([np.repeat(per, 3), np.ones(r.size - 3 * m)])


def _huber_cost(r: np.ndarray, m: int, scale: float) -> float:
    """Σ ρ(‖e‖) over the constraints (ρ(e) = e²/2 within ``scale``, scale·(e − scale/2)
    beyond) plus ½‖r‖² of the anchor rows."""
    norms = np.linalg.norm(r[: 3 * m].reshape(m, 3), axis=1)
    rho = np.where(norms <= scale, 0.5 * norms**2, scale * (norms - 0.5 * scale))
    return float(rho.sum() + 0.5 * np.sum(r[3 * m :] ** 2))
