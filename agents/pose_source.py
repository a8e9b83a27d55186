"""Where the agent believes it is. One small interface, so SLAM can replace odometry."""

from __future__ import annotations

from typing import Protocol

import numpy as np

from fleet.protocol import LaserScan, Odometry


class PoseSource(Protocol):
    """Fed with odometry and scans; answers the current pose estimate and its covariance."""

    name: str

    def on_odometry(self, msg: Odometry) -> None: ...

    def on_scan(self, msg: LaserScan) -> None: ...

    def pose(self) -> tuple[float, float, float]: ...

    def covariance(self) -> np.ndarray: ...


class OdometryPose:
    """Dead reckoning: the odometry pose, which starts at the spawn pose (as the dock is known)."""

    name = "odometry"

    def __init__(self, start: tuple[float, float, float]) -> None:
        self._pose = start

    def on_odometry(self, msg: Odometry) -> None:
        self._pose = (msg.x, msg.y, msg.theta)

    def on_scan(self, msg: LaserScan) -> None:
        return None

    def pose(self) -> tuple[float, float, float]:
        return self._pose

    def covariance(self) -> np.ndarray:
        return np.zeros(9)
