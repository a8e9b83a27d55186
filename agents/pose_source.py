"""Where the agent believes it is. One small interface, so SLAM can replace odometry."""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from agents.slam.geometry import compose, relative
from agents.slam.params import SlamParams
from agents.slam.slam import Slam
from agents.slam.slam_map import SlamMap
from fleet.protocol import LaserScan, Odometry

Pose = tuple[float, float, float]


ODOM_HISTORY = 64


class PoseSource(Protocol):
    """Fed with odometry and scans; answers the current pose estimate and its covariance."""

    name: str

    def on_odometry(self, msg: Odometry) -> None: ...

    def on_scan(self, msg: LaserScan) -> None: ...

    def pose(self) -> Pose: ...

    def covariance(self) -> np.ndarray: ...

    def occupancy(self) -> SlamMap | None: ...


class OdometryPose:
    """Dead reckoning: the odometry pose, which starts at the spawn pose (as the dock is known)."""

    name = "odometry"

    def __init__(self, start: Pose) -> None:
        self._pose = start

    def on_odometry(self, msg: Odometry) -> None:
        self._pose = (msg.x, msg.y, msg.theta)

    def on_scan(self, msg: LaserScan) -> None:
        return None

    def pose(self) -> Pose:
        return self._pose

    def covariance(self) -> np.ndarray:
        return np.zeros(9)

    def occupancy(self) -> SlamMap | None:
        return None


def odometry_at(history: Sequence[tuple[float, Pose]], stamp: float) -> Pose:
    """The odometry pose at ``stamp`` from (stamp, pose) messages in time order: interpolated
    along the relative motion between the two around it, the nearest one outside them."""
    times = np.array([t for t, _ in history])
    k = int(np.searchsorted(times, stamp))
    if k == 0:
        return history[0][1]
    if k == len(times):
        return history[-1][1]
    (t0, a), (t1, b) = history[k - 1], history[k]
    x, y, theta = compose(a, (stamp - t0) / (t1 - t0) * relative(a, b))
    return (float(x), float(y), float(theta))


class SlamPose:
    """The agent's own SLAM (``agents.slam``), its map frame tied to the world by the spawn pose.

    Each scan is matched with the odometry pose at the scan's stamp as the prior (interpolated
    in the recent odometry, which may arrive before or after the scan); between scans the pose
    follows the odometry increments since that stamp, so a control step always sees the
    freshest estimate. Pairing a scan with odometry from another moment would count the motion
    between the two twice — centimetres and degrees at full speed.
    """

    name = "slam"

    def __init__(self, params: SlamParams, start: Pose, range_min: float, range_max: float) -> None:
        self._slam = Slam(params, start, range_min=range_min, range_max=range_max)
        self._odom: Pose | None = None
        self._history: deque[tuple[float, Pose]] = deque(maxlen=ODOM_HISTORY)
        self._odom_at_scan: Pose | None = None
        self._at_scan: Pose = start
        self._covariance = np.zeros(9)

    def on_odometry(self, msg: Odometry) -> None:
        if self._history and msg.stamp <= self._history[-1][0]:
            return
        self._odom = (msg.x, msg.y, msg.theta)
        self._history.append((msg.stamp, self._odom))

    def on_scan(self, msg: LaserScan) -> None:
        if self._odom is None:
            return
        odom = odometry_at(self._history, msg.stamp)
        est = self._slam.process(
            msg.ranges.astype(np.float64), msg.angle_min, msg.angle_increment, odom, msg.stamp
        )
        self._at_scan = est.pose
        self._odom_at_scan = odom
        self._covariance = est.covariance.reshape(9)

    def pose(self) -> Pose:
        if self._odom is None or self._odom_at_scan is None:
            return self._at_scan
        x, y, theta = compose(self._at_scan, relative(self._odom_at_scan, self._odom))
        return (float(x), float(y), float(theta))

    def covariance(self) -> np.ndarray:
        return self._covariance.copy()

    def occupancy(self) -> SlamMap | None:
        return self._slam.occupancy()
