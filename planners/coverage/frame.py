"""A grid rotated so that a region's dominant wall direction becomes the row direction."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from planners.grid import GridMap


@dataclass(frozen=True)
class RotatedFrame:
    """Cells of a grid whose rows run along world heading ``angle``.

    Rotated cell (i, j) has its centre at rotated coordinates ``q0 + (j, i)·resolution``, and
    world point ``p = R(angle)·q``.
    """

    angle: float
    q0: tuple[float, float]
    resolution: float
    shape: tuple[int, int]

    def to_world(self, rc: np.ndarray) -> np.ndarray:
        """(..., 2) continuous (row, col) in this frame → (..., 2) world (x, y)."""
        rc = np.asarray(rc, dtype=float)
        qx = self.q0[0] + rc[..., 1] * self.resolution
        qy = self.q0[1] + rc[..., 0] * self.resolution
        c, s = math.cos(self.angle), math.sin(self.angle)
        return np.stack([c * qx - s * qy, s * qx + c * qy], axis=-1)

    def from_world(self, xy: np.ndarray) -> np.ndarray:
        """(..., 2) world (x, y) → (..., 2) continuous (row, col) in this frame."""
        xy = np.asarray(xy, dtype=float)
        c, s = math.cos(self.angle), math.sin(self.angle)
        qx = c * xy[..., 0] + s * xy[..., 1]
        qy = -s * xy[..., 0] + c * xy[..., 1]
        return np.stack(
            [(qy - self.q0[1]) / self.resolution, (qx - self.q0[0]) / self.resolution], axis=-1
        )


def frame_for(grid: GridMap, mask: np.ndarray, angle: float, margin: int = 1) -> RotatedFrame:
    """The smallest rotated frame (``margin`` cells around) holding every cell of ``mask``."""
    pts = grid.cell_to_world(np.argwhere(mask))
    c, s = math.cos(angle), math.sin(angle)
    qx = c * pts[:, 0] + s * pts[:, 1]
    qy = -s * pts[:, 0] + c * pts[:, 1]
    res = grid.resolution
    q0 = (float(qx.min()) - margin * res, float(qy.min()) - margin * res)
    shape = (
        math.ceil((qy.max() - q0[1]) / res) + margin + 1,
        math.ceil((qx.max() - q0[0]) / res) + margin + 1,
    )
    return RotatedFrame(angle, q0, res, shape)


def resample(grid: GridMap, mask: np.ndarray, frame: RotatedFrame) -> np.ndarray:
    """``mask`` seen in ``frame``: a rotated cell takes the value of the grid cell holding its
    centre."""
    ii, jj = np.indices(frame.shape)
    rc = grid.world_to_cell(frame.to_world(np.stack([ii, jj], axis=-1)))
    inside = grid.in_bounds(rc)
    out = np.zeros(frame.shape, dtype=bool)
    out[inside] = mask[rc[inside][:, 0], rc[inside][:, 1]]
    return out


def dominant_direction(mask: np.ndarray) -> float:
    """The dominant edge direction (rad, in [0, π/2)) of a region's outline.

    Gradient orientation histogram of the smoothed region mask (Sobel), folded modulo 90° since
    indoor walls meet mostly at right angles; the peak of the magnitude-weighted histogram is
    refined by the circular mean of the angles near it.
    """
    img = ndimage.gaussian_filter(mask.astype(float), 1.0)
    gy = ndimage.sobel(img, axis=0)
    gx = ndimage.sobel(img, axis=1)
    mag = np.hypot(gx, gy)
    sel = mag > 0.05 * mag.max() if mag.max() > 0 else mag > 0
    if not sel.any():
        return 0.0
    theta = np.mod(np.arctan2(gy[sel], gx[sel]), math.pi / 2)
    w = mag[sel]
    bins = 90
    hist = np.bincount((theta / (math.pi / 2) * bins).astype(int) % bins, weights=w, minlength=bins)
    hist = ndimage.uniform_filter1d(hist, 5, mode="wrap")
    peak = (np.argmax(hist) + 0.5) * (math.pi / 2) / bins
    near = np.abs((theta - peak + math.pi / 4) % (math.pi / 2) - math.pi / 4) < math.radians(4)
    z = np.sum(w[near] * np.exp(4j * theta[near]))
    return float(np.mod(np.angle(z) / 4, math.pi / 2))
