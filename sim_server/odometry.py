"""Simulated wheel odometry with random and systematic drift.

Follows the odometry motion model of Thrun, Burgard, Fox, *Probabilistic Robotics* (2005),
§5.4: each step of the true motion is decomposed into a rotation ``rot1`` towards the direction
of travel, a translation ``trans`` and a final rotation ``rot2``; each part is corrupted by
zero-mean Gaussian noise and the noisy motion is composed onto the odometry pose.

Two refinements over the book's table 5.6:

* The noise *variances* grow linearly with the distance and angle of the step (a random walk),
  where the book uses squared increments. Linear variances make the accumulated drift
  independent of the odometry rate: after driving ``D`` metres straight the heading error std is
  ``alpha_trans_rot·√D`` whether the odometry runs at 20 or 50 Hz. So each ``alpha`` is the
  error std after one metre (or radian) of motion::

      var(rot1)  = alpha_rot²·|rot1| + ½·alpha_trans_rot²·|trans|
      var(trans) = alpha_trans²·|trans| + alpha_rot_trans²·(|rot1| + |rot2|)
      var(rot2)  = alpha_rot²·|rot2| + ½·alpha_trans_rot²·|trans|

* Driving backwards is a negative translation, not a half turn (as ROS amcl does), and a step
  too short to have a meaningful bearing counts all of its rotation as ``rot2`` in the noise.

A systematic heading bias (a wheel-size mismatch) adds ``heading_bias_per_m`` radians per metre
of signed travel, half before and half after the translation, so the odometry curves the way a
real robot's dead reckoning does.
"""

from __future__ import annotations

import math

import numpy as np

from fleet.params import OdometryParams

# Below this step length (m) the direction of travel is noise (physics jitter during a turn in
# place), so its bearing is not counted as rotation in the noise model.
_MIN_BEARING_STEP = 1e-4


def wrap_angle(a: np.ndarray | float) -> np.ndarray:
    """Angles wrapped into [−π, π)."""
    return np.mod(np.asarray(a) + math.pi, 2 * math.pi) - math.pi


def decompose_motion(prev: np.ndarray, cur: np.ndarray) -> tuple[np.ndarray, ...]:
    """(…, 3) poses x, y, θ → (rot1, trans, rot2) of the motion between them.

    ``trans`` is signed: negative when the robot moved backwards, in which case ``rot1`` is the
    turn towards the reversed direction of travel.
    """
    dx = cur[..., 0] - prev[..., 0]
    dy = cur[..., 1] - prev[..., 1]
    trans = np.hypot(dx, dy)
    rot1 = wrap_angle(np.arctan2(dy, dx) - prev[..., 2])
    backwards = np.abs(rot1) > math.pi / 2
    rot1 = np.where(backwards, wrap_angle(rot1 - math.pi), rot1)
    trans = np.where(backwards, -trans, trans)
    rot2 = wrap_angle(cur[..., 2] - prev[..., 2] - rot1)
    return rot1, trans, rot2


def odometry_step(
    odom: np.ndarray,
    prev_true: np.ndarray,
    cur_true: np.ndarray,
    params: OdometryParams,
    normals: np.ndarray,
) -> np.ndarray:
    """The odometry pose after the true motion ``prev_true → cur_true`` (all (…, 3) poses).

    ``normals`` (…, 3) are standard normal draws for the noise of rot1, trans and rot2.
    """
    rot1, trans, rot2 = decompose_motion(prev_true, cur_true)
    dist = np.abs(trans)
    bearing_ok = dist >= _MIN_BEARING_STEP
    turn1 = np.where(bearing_ok, np.abs(rot1), 0.0)
    turn2 = np.where(bearing_ok, np.abs(rot2), np.abs(wrap_angle(rot1 + rot2)))
    half_drift = 0.5 * params.alpha_trans_rot**2 * dist
    sd_rot1 = np.sqrt(params.alpha_rot**2 * turn1 + half_drift)
    sd_trans = np.sqrt(params.alpha_trans**2 * dist + params.alpha_rot_trans**2 * (turn1 + turn2))
    sd_rot2 = np.sqrt(params.alpha_rot**2 * turn2 + half_drift)
    half_bias = 0.5 * params.heading_bias_per_m * trans
    rot1 = rot1 + sd_rot1 * normals[..., 0] + half_bias
    trans = trans + sd_trans * normals[..., 1]
    rot2 = rot2 + sd_rot2 * normals[..., 2]
    heading = odom[..., 2] + rot1
    return np.stack(
        [
            odom[..., 0] + trans * np.cos(heading),
            odom[..., 1] + trans * np.sin(heading),
            wrap_angle(heading + rot2 + half_bias),
        ],
        axis=-1,
    )


class OdometryModel:
    """Wheel odometry of one robot (pose shape (3,)) or of N robots at once (shape (N, 3)).

    Odometry starts at the robot's true start pose, as a robot knows its dock. Call
    :meth:`update` with the current true pose(s) at the odometry rate; it returns the odometry
    pose(s). One call for N robots costs about as much as one call for one robot, and draws the
    same noise as N single-robot models sharing the generator would, in row order. Robots join
    and leave an (N, 3) model with :meth:`add` and :meth:`remove`.
    """

    def __init__(
        self,
        params: OdometryParams,
        rng: np.random.Generator,
        initial_pose: tuple[float, float, float] | np.ndarray,
    ) -> None:
        self.params = params
        self.rng = rng
        self._true = np.array(initial_pose, dtype=np.float64)
        if self._true.shape[-1:] != (3,) or self._true.ndim > 2:
            raise ValueError(
                f"OdometryModel: initial_pose must be (3,) or (N, 3), got {self._true.shape}"
            )
        self._odom = self._true.copy()

    @property
    def pose(self) -> np.ndarray:
        """The current odometry pose(s) x, y, θ."""
        return self._odom.copy()

    def update(self, true_pose: tuple[float, float, float] | np.ndarray) -> np.ndarray:
        """Advance by the true motion since the last call; returns the odometry pose(s)."""
        cur = np.array(true_pose, dtype=np.float64)
        if cur.shape != self._true.shape:
            raise ValueError(
                f"OdometryModel.update: expected shape {self._true.shape}, got {cur.shape}"
            )
        normals = self.rng.standard_normal(cur.shape)
        self._odom = odometry_step(self._odom, self._true, cur, self.params, normals)
        self._true = cur
        return self._odom.copy()

    def add(
        self,
        initial_pose: tuple[float, float, float],
        odometry: tuple[float, float, float] | None = None,
    ) -> None:
        """Append a robot as the last row; its odometry starts at ``odometry`` (by default its
        true ``initial_pose``)."""
        if self._true.ndim != 2:
            raise ValueError("OdometryModel.add: only a model of shape (N, 3) takes robots")
        row = np.array(initial_pose, dtype=np.float64).reshape(1, 3)
        start = row if odometry is None else np.array(odometry, dtype=np.float64).reshape(1, 3)
        self._true = np.vstack([self._true, row])
        self._odom = np.vstack([self._odom, start])

    def remove(self, index: int) -> None:
        """Drop the robot in row ``index``; later rows move up by one."""
        if self._true.ndim != 2:
            raise ValueError("OdometryModel.remove: only a model of shape (N, 3) has rows")
        self._true = np.delete(self._true, index, axis=0)
        self._odom = np.delete(self._odom, index, axis=0)
