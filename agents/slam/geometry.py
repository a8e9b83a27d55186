"""SE(2) poses as (x, y, theta) arrays: composition, inversion, relative poses, scan points.

Poses broadcast over leading axes, so a whole trajectory is transformed at once.
"""

from __future__ import annotations

import numpy as np


def wrap_angle(a: np.ndarray | float) -> np.ndarray | float:
    """Angles mapped to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a ⊕ b: the pose b, given in the frame of a, expressed in a's parent frame."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    out[..., 1] = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    out[..., 2] = wrap_angle(a[..., 2] + b[..., 2])
    return out


def inverse(a: np.ndarray) -> np.ndarray:
    """a⁻¹, so that a ⊕ a⁻¹ is the identity."""
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    out = np.empty(a.shape)
    out[..., 0] = -c * a[..., 0] - s * a[..., 1]
    out[..., 1] = s * a[..., 0] - c * a[..., 1]
    out[..., 2] = wrap_angle(-a[..., 2])
    return out


def relative(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a⁻¹ ⊕ b: the pose b seen from a."""
    return compose(inverse(a), b)


def transform_points(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N, 2) points in the frame ``pose`` → the parent frame."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    rot = np.array([[c, -s], [s, c]])
    return points @ rot.T + np.asarray(pose[:2])


def scan_to_points(
    ranges: np.ndarray,
    angle_min: float,
    angle_increment: float,
    range_min: float,
    range_max: float,
) -> np.ndarray:
    """Beam endpoints (N, 2) in the sensor frame for ranges within [range_min, range_max).

    Beams outside that interval (and NaN/inf) are "no return" and are dropped: they carry no
    reliable evidence about free space (glass, black surfaces, open doors beyond range).
    """
    r = np.asarray(ranges, dtype=float)
    angles = angle_min + angle_increment * np.arange(r.size)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(r) & (r >= range_min) & (r < range_max)
    return np.stack([r[ok] * np.cos(angles[ok]), r[ok] * np.sin(angles[ok])], axis=-1)


def missing_rays(
    ranges: np.ndarray,
    angle_min: float,
    angle_increment: float,
    range_max: float,
    length: float,
) -> np.ndarray:
    """Ends (M, 2), in the sensor frame, of rays ``length`` long along the beams that saw
    nothing within ``range_max`` (a reading of ``range_max`` or more, or +inf): the free space
    such a beam crossed, with no hit at its end (Cartographer's ``missing_data_ray_length``,
    Hess et al. 2016). Readings below the range, NaN and -inf (too near, invalid) give none."""
    r = np.asarray(ranges, dtype=float)
    angles = angle_min + angle_increment * np.arange(r.size)
    with np.errstate(invalid="ignore"):
        none = (r >= range_max) & (length > 0)
    return length * np.stack([np.cos(angles[none]), np.sin(angles[none])], axis=-1)
