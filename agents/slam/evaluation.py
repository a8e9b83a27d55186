"""Trajectory error metrics for SLAM: absolute trajectory error and relative pose error.

Trajectories are (N, 3) arrays of poses x, y, θ (metres, radians) or (N, 4) rows t, x, y, θ
(the last three columns are used). Estimate and reference are paired row by row; use
:func:`associate` first when they were sampled at different times.

- ATE (Sturm et al., IROS 2012): the RMSE of the position differences,
  ``sqrt(1/N Σ‖p_i − p*_i‖²)``, optionally after the rigid motion that best aligns the
  estimate with the reference (:func:`align_rigid_2d`).
- RPE (Kümmerle et al., "On measuring the accuracy of SLAM algorithms", Autonomous Robots
  2009): for a set of pose pairs (i, j), the relative motions ``δ_ij = x_i⁻¹ ⊕ x_j`` of the
  estimate and ``δ*_ij`` of the reference are compared through ``e_ij = δ*_ij⁻¹ ⊕ δ_ij``;
  the translational error is ``‖trans(e_ij)‖`` and the rotational error ``|rot(e_ij)|``. The
  paper's metric is ``ε = 1/N Σ trans(e)² + rot(e)²``; we report the two parts separately, as
  means (the figures the paper tabulates) and as RMSEs. Errors of relative motions do not
  accumulate along the trajectory, so an early heading error does not dominate the figure the
  way it dominates ATE.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agents.slam.geometry import compose, relative, wrap_angle


def _poses(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.ndim != 2 or a.shape[1] not in (3, 4):
        raise ValueError(f"expected (N, 3) poses or (N, 4) rows t, x, y, theta, got {a.shape}")
    return a[:, -3:]


def associate(t_est: np.ndarray, t_ref: np.ndarray, max_dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (into ``t_est``, into ``t_ref``) of the nearest reference time to each
    estimate time, kept where they differ by at most ``max_dt``. ``t_ref`` must be sorted."""
    t_est = np.asarray(t_est, dtype=float)
    t_ref = np.asarray(t_ref, dtype=float)
    if len(t_ref) == 0 or len(t_est) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    right = np.clip(np.searchsorted(t_ref, t_est), 0, len(t_ref) - 1)
    left = np.clip(right - 1, 0, len(t_ref) - 1)
    nearest = np.where(np.abs(t_ref[left] - t_est) <= np.abs(t_ref[right] - t_est), left, right)
    ok = np.abs(t_ref[nearest] - t_est) <= max_dt
    return np.flatnonzero(ok), nearest[ok]


def align_rigid_2d(est_xy: np.ndarray, ref_xy: np.ndarray) -> np.ndarray:
    """The pose (x, y, θ) of the rotation + translation that maps ``est_xy`` closest to
    ``ref_xy`` in least squares (Umeyama 1991 without scale)."""
    est_xy = np.asarray(est_xy, dtype=float)
    ref_xy = np.asarray(ref_xy, dtype=float)
    mu_e, mu_r = est_xy.mean(axis=0), ref_xy.mean(axis=0)
    e, r = est_xy - mu_e, ref_xy - mu_r
    theta = math.atan2(
        float(np.sum(e[:, 0] * r[:, 1] - e[:, 1] * r[:, 0])),
        float(np.sum(e[:, 0] * r[:, 0] + e[:, 1] * r[:, 1])),
    )
    c, s = math.cos(theta), math.sin(theta)
    t = mu_r - np.array([c * mu_e[0] - s * mu_e[1], s * mu_e[0] + c * mu_e[1]])
    return np.array([t[0], t[1], theta])


def ate_rmse(est: np.ndarray, ref: np.ndarray, align: bool = False) -> float:
    """Absolute trajectory error: RMSE of the position differences of paired rows. With
    ``align`` the estimate is first moved by :func:`align_rigid_2d`."""
    est_xy = _poses(est)[:, :2]
    ref_xy = _poses(ref)[:, :2]
    if est_xy.shape != ref_xy.shape or len(est_xy) == 0:
        raise ValueError(f"need equally many poses, got {len(est_xy)} and {len(ref_xy)}")
    if align:
        pose = align_rigid_2d(est_xy, ref_xy)
        est_xy = compose(pose, np.column_stack([est_xy, np.zeros(len(est_xy))]))[:, :2]
    return float(np.sqrt(np.mean(np.sum((est_xy - ref_xy) ** 2, axis=1))))


def pairs_by_time(t: np.ndarray, delta: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i, j): every pose i with the first pose j at least ``delta`` seconds later."""
    t = np.asarray(t, dtype=float)
    j = np.searchsorted(t, t + delta - 1e-9)
    ok = j < len(t)
    return np.flatnonzero(ok), j[ok]


def pairs_by_distance(ref: np.ndarray, delta: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i, j): every pose i with the first pose j after which the reference has travelled
    at least ``delta`` metres along its path (Kümmerle et al.'s fixed-distance variant)."""
    ref_xy = _poses(ref)[:, :2]
    travelled = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(ref_xy, axis=0).T))])
    j = np.searchsorted(travelled, travelled + delta - 1e-9)
    ok = j < len(travelled)
    return np.flatnonzero(ok), j[ok]


@dataclass(frozen=True)
class RelativePoseError:
    """Kümmerle et al. 2009 relative pose error over ``pairs`` pose pairs (metres, radians)."""

    pairs: int
    trans_mean: float
    rot_mean: float
    trans_rmse: float
    rot_rmse: float


def relative_pose_error(
    est: np.ndarray, ref: np.ndarray, i: np.ndarray, j: np.ndarray
) -> RelativePoseError:
    """RPE of the estimate against the reference over the pose pairs (i[k], j[k]); ``est`` and
    ``ref`` are paired row by row. See the module docstring for the formula."""
    est = _poses(est)
    ref = _poses(ref)
    if est.shape != ref.shape:
        raise ValueError(f"need equally many poses, got {len(est)} and {len(ref)}")
    if len(i) == 0:
        raise ValueError("no pose pairs: the trajectory is shorter than the pair spacing")
    delta = relative(est[i], est[j])
    delta_ref = relative(ref[i], ref[j])
    err = relative(delta_ref, delta)
    trans = np.hypot(err[:, 0], err[:, 1])
    rot = np.abs(wrap_angle(err[:, 2]))
    return RelativePoseError(
        len(trans),
        float(trans.mean()),
        float(rot.mean()),
        float(np.sqrt(np.mean(trans**2))),
        float(np.sqrt(np.mean(rot**2))),
    )


def pairs_by_index(n: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i, i + k) over n poses: the relations "k scans apart" of Kümmerle et al. 2009."""
    i = np.arange(max(n - k, 0))
    return i, i + k


RPE_SCAN_STEPS = (1, 5, 20)


def trajectory_scores(est: np.ndarray, ref: np.ndarray, prefix: str = "") -> dict[str, float]:
    """The figures the log benchmarks quote for one trajectory against its reference (paired
    row by row): translational RPE (mean over every pair of poses 1, 5 and 20 scans apart,
    Kümmerle et al. 2009) and rotational RPE in degrees, and ATE RMSE after the rigid alignment
    of :func:`align_rigid_2d` (Sturm et al. 2012). Keys start with ``prefix``; a step longer
    than the trajectory is left out."""
    out: dict[str, float] = {}
    n = len(_poses(est))
    for k in RPE_SCAN_STEPS:
        if n <= k:
            continue
        rpe = relative_pose_error(est, ref, *pairs_by_index(n, k))
        out[f"{prefix}rpe{k}_m"] = rpe.trans_mean
        out[f"{prefix}rpe{k}_deg"] = math.degrees(rpe.rot_mean)
    out[f"{prefix}ate_m"] = ate_rmse(est, ref, align=True)
    return out
