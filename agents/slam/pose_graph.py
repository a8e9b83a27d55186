"""A 2D pose graph optimized by sparse nonlinear least squares (Gauss–Newton, sparse solve).

Every constraint says "pose b seen from pose a is z": residual r = (a⁻¹ ⊕ b) ⊖ z, whitened by
its standard deviations (the SPA formulation of Konolige et al. 2010, as used for submaps and
scan nodes in Hess et al. 2016). A Huber loss bounds the pull of a wrong loop closure. The
Jacobian is analytic and sparse: each constraint touches six variables.

On a long run the graph is optimized over a window of the newest poses only: older poses are
held where the last optimization that reached them left them, and constraints between two held
poses leave the graph (the fixed-lag idea of incremental smoothers, Kaess et al. 2008, iSAM;
Cartographer's pure localization trims old trajectory nodes the same way, Hess et al. 2016).
A new scan that closes a loop against an old submap is pulled onto it, as a robot localizing on
a finished map; memory and time per optimization stay bounded however long the robot drives.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from agents.slam.geometry import wrap_angle


@dataclass(frozen=True)
class OptimizationReport:
    """Gauss–Newton iterations used and the Huber cost of the whitened residuals before and
    after."""

    iterations: int
    initial_cost: float
    final_cost: float


class PoseGraph:
    """Poses (x, y, θ) and relative-pose constraints; pose 0 is held fixed (the gauge).

    ``window``: the optimization moves only the newest ``window`` poses (0: every pose)."""

    def __init__(self, window: int = 0) -> None:
        if window < 0:
            raise ValueError(f"window must be >= 0, got {window}")
        self.window = window
        # poses and constraints grow by doubling: a pose costs 24 bytes, a constraint one
        # 64-byte row (a, b, z (3), weights 1/σ (3)), not a list entry and small arrays each
        self._pose_rows = np.zeros((64, 3))
        self._n = 0
        self._rows = np.zeros((64, 8))
        self._m = 0
        self._held = 0

    @property
    def poses(self) -> np.ndarray:
        return self._pose_rows[: self._n]

    @property
    def num_constraints(self) -> int:
        return self._m

    @property
    def held(self) -> int:
        """Poses below this index are held fixed: older than the optimization window."""
        return self._held

    def add_pose(self, pose: np.ndarray) -> int:
        if self._n == len(self._pose_rows):
            self._pose_rows = np.vstack([self._pose_rows, np.zeros_like(self._pose_rows)])
        self._pose_rows[self._n] = np.asarray(pose, dtype=float)
        self._n += 1
        return self._n - 1

    def set_pose(self, index: int, pose: np.ndarray) -> None:
        self._pose_rows[index] = pose

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
        normal equations JᵀWJ·δ = −JᵀWr, symmetric positive definite, as a sparse Cholesky
        solver would (SuperLU in its symmetric mode: a minimum-degree ordering of JᵀWJ + WJᵀJ's
        pattern and pivots kept on the diagonal; COLAMD with partial pivoting, for matrices of
        any kind, took 5.5 × as long on the 600 s home route); it stops when no variable moves
        by ``tolerance`` or after ``max_iterations``."""
        if not self._m:
            return OptimizationReport(0, 0.0, 0.0)
        self._hold_old()
        rows = self._rows[: self._m]
        a = rows[:, 0].astype(np.int64)
        b = rows[:, 1].astype(np.int64)
        z = rows[:, 2:5]
        w = rows[:, 5:8]
        n, free = self._n, self._held
        m = a.size
        # with no pose held, pose 0 is pinned by a stiff prior (the gauge); else the held do it
        anchored = free == 0
        anchor = self._pose_rows[0].copy()
        anchor_w = 1e4
        full = self._pose_rows[:n].copy()

        def residuals(flat: np.ndarray) -> np.ndarray:
            full[free:] = flat.reshape(n - free, 3)
            pa, pb = full[a], full[b]
            c, s = np.cos(pa[:, 2]), np.sin(pa[:, 2])
            dx, dy = pb[:, 0] - pa[:, 0], pb[:, 1] - pa[:, 1]
            r = np.empty((m, 3))
            r[:, 0] = c * dx + s * dy - z[:, 0]
            r[:, 1] = -s * dx + c * dy - z[:, 1]
            r[:, 2] = wrap_angle(pb[:, 2] - pa[:, 2] - z[:, 2])
            r *= w
            if not anchored:
                return r.reshape(-1)
            return np.concatenate([r.reshape(-1), anchor_w * (full[0] - anchor)])

        row_idx, col_idx, moving = _jacobian_pattern(a, b, free, anchored)
        n_rows = 3 * m + (3 if anchored else 0)

        def jacobian(flat: np.ndarray) -> sp.csr_matrix:
            full[free:] = flat.reshape(n - free, 3)
            pa, pb = full[a], full[b]
            c, s = np.cos(pa[:, 2]), np.sin(pa[:, 2])
            dx, dy = pb[:, 0] - pa[:, 0], pb[:, 1] - pa[:, 1]
            jx = np.stack([-c, -s, -s * dx + c * dy, c, s], axis=1) * w[:, :1]
            jy = np.stack([s, -c, -c * dx - s * dy, -s, c], axis=1) * w[:, 1:2]
            jt = np.stack([-np.ones(m), np.ones(m)], axis=1) * w[:, 2:3]
            data = np.concatenate([jx.reshape(-1), jy.reshape(-1), jt.reshape(-1)])[moving]
            if anchored:
                data = np.concatenate([data, np.full(3, anchor_w)])
            return sp.csr_matrix((data, (row_idx, col_idx)), shape=(n_rows, 3 * (n - free)))

        # A tiny Levenberg damping keeps poses that no constraint touches yet (a submap just
        # started) from making the normal equations singular; it moves nothing else.
        damping = sp.identity(3 * (n - free), format="csr") * 1e-9
        x = self._pose_rows[free:n].reshape(-1).copy()
        initial = final = _huber_cost(residuals(x), m, huber_scale)
        iterations = 0
        while iterations < max_iterations:
            iterations += 1
            r = residuals(x)
            jac = jacobian(x)
            weights = _huber_weights(r, m, huber_scale)
            jw = sp.diags(weights) @ jac
            h = (jac.T @ jw + damping).tocsc()
            step = _solve_spd(h, -(jw.T @ r))
            x += step
            final = _huber_cost(residuals(x), m, huber_scale)
            if np.max(np.abs(step)) < tolerance:
                break
        x = x.reshape(n - free, 3)
        x[:, 2] = wrap_angle(x[:, 2])
        self._pose_rows[free:n] = x
        return OptimizationReport(iterations, initial, final)

    def _hold_old(self) -> None:
        """Hold every pose older than the window, and drop the constraints between two held
        poses: nothing can move them any more."""
        if not self.window or self._n - self._held <= self.window:
            return
        self._held = self._n - self.window
        rows = self._rows[: self._m]
        live = rows[(rows[:, 0] >= self._held) | (rows[:, 1] >= self._held)]
        self._rows[: len(live)] = live
        self._m = len(live)


def _solve_spd(h: sp.csc_matrix, rhs: np.ndarray) -> np.ndarray:
    """``h⁻¹ rhs`` for a sparse symmetric positive definite ``h`` (see :meth:`optimize`)."""
    lu = splu(h, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    return lu.solve(rhs)


def _jacobian_pattern(
    a: np.ndarray, b: np.ndarray, free: int, anchored: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows and columns of the Jacobian's entries, five per x and y residual and two per θ
    residual (then the gauge's three), columns counted from the first pose not held; and which
    of the constraints' entries stay (those of held poses leave)."""
    m = a.size
    rows3 = 3 * np.arange(m)
    row_idx = np.concatenate(
        [np.repeat(rows3, 5), np.repeat(rows3 + 1, 5), np.repeat(rows3 + 2, 2)]
    )
    cols_xy = np.stack([3 * a, 3 * a + 1, 3 * a + 2, 3 * b, 3 * b + 1], axis=1).reshape(-1)
    cols_t = np.stack([3 * a + 2, 3 * b + 2], axis=1).reshape(-1)
    col_idx = np.concatenate([cols_xy, cols_xy, cols_t]) - 3 * free
    moving = col_idx >= 0
    row_idx, col_idx = row_idx[moving], col_idx[moving]
    if anchored:
        row_idx = np.concatenate([row_idx, 3 * m + np.arange(3)])
        col_idx = np.concatenate([col_idx, np.arange(3)])
    return row_idx, col_idx, moving


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
