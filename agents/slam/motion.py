"""The odometry motion model of the SLAM: how uncertain one odometry step is, and what that makes
the tracking prior weigh. Loop closure grows its search window with the same model."""

from __future__ import annotations

import math

import numpy as np

from fleet.slam_params import SlamParams


def step_sigmas(params: SlamParams, step: np.ndarray) -> tuple[float, float]:
    """Standard deviations (σ_xy per axis, σ_θ) of the odometry error of one ``step``
    (dx, dy, dθ) under the linear motion model of ``SlamParams``."""
    dd = math.hypot(step[0], step[1])
    sigma_xy = params.motion_xy_per_m * dd + params.motion_xy_floor
    sigma_theta = params.motion_theta_per_rad * abs(step[2]) + params.motion_theta_per_m * dd
    return sigma_xy, sigma_theta


def tracking_window(params: SlamParams, step: np.ndarray) -> tuple[float, float]:
    """Half-widths (m, rad) of the scan-to-submap search for one ``step``: Olson's window
    (Olson 2009, §III) sized by the prior's uncertainty, ``search_window_sigmas`` standard
    deviations of the step's odometry error (:func:`step_sigmas`), at least
    ``search_window_min_xy``/``_theta`` (wheel slip against a wall or a peer is not in the
    model) and at most ``search_window_xy``/``_theta``."""
    sigma_xy, sigma_theta = step_sigmas(params, step)
    k = params.search_window_sigmas
    xy = min(params.search_window_xy, max(params.search_window_min_xy, k * sigma_xy))
    theta = min(params.search_window_theta, max(params.search_window_min_theta, k * sigma_theta))
    return xy, theta


def prior_penalties(params: SlamParams, step: np.ndarray) -> tuple[float, float]:
    """Score penalties per m² and rad² for leaving the odometry prior of one ``step``.

    The step's odometry uncertainty follows the linear motion model of ``SlamParams``
    (σ_xy = a·dd + b, σ_θ = c·|dθ| + d·dd, as Thrun et al., Probabilistic Robotics §5.4,
    with standard deviations instead of variances). A Gaussian prior with that σ, weighed
    against the scan's mean likelihood, costs prior_weight·d²/σ²; the penalty is that,
    capped by the fixed translation_penalty / rotation_penalty, which hold for short steps
    (where the odometry is better than any scan in a featureless corridor)."""
    sigma_xy, sigma_theta = step_sigmas(params, step)
    t_pen = min(params.translation_penalty, params.prior_weight / sigma_xy**2)
    r_pen = params.rotation_penalty
    if sigma_theta > 0:
        r_pen = min(r_pen, params.prior_weight / sigma_theta**2)
    return t_pen, r_pen


def within_refinement(params: SlamParams, step: np.ndarray) -> bool:
    """Whether the odometry error of one ``step``, at ``search_window_sigmas`` standard
    deviations, stays within ``track_prior_xy`` and ``track_prior_theta``: a prior that near
    lies in the likelihood field's basin, and the refinement alone may place the scan; a
    farther one (sparse scans, fast turns) may let the fit settle on a wrong wall, and the
    scan is searched."""
    sigma_xy, sigma_theta = step_sigmas(params, step)
    k = params.search_window_sigmas
    return k * sigma_xy <= params.track_prior_xy and k * sigma_theta <= params.track_prior_theta
