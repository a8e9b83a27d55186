"""SLAM for a robot that does not know where it stands: mapped in its own frame until the fleet
places it.

A robot started with no known pose (``--unknown-start``) has wheel odometry that starts at
(0, 0, 0) wherever it was switched on, so its SLAM runs in a frame of its own: the pose where it
woke is the origin. Its map goes out marked ``own_frame``; the coordinator matches it with the
fleet's merged map (``planners.map_match.place_map``: a search over every rotation and
translation, Olson 2009, taken only when confident, Birk and Carpin 2006) and answers with the
transform of its frame into the fleet's (``coord/placement/<robot>``). Until then the robot is
not localized: it stands, bids on nothing, and tells no pose or intent (a pose in its own frame
would put it somewhere else on every peer's map).

Placed, it starts a fresh SLAM at its pose carried into the fleet's frame and given the recent
odometry and the last scan, as a respawned robot does once found in its saved map
(:class:`agents.pose_source.RelocalizingSlamPose`). The own-frame map is dropped: the robot saw
it from where it stood, and sees it again with its first fleet-frame scan.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from agents.pose_source import ODOM_HISTORY, Pose, SlamPose
from agents.slam.geometry import compose
from agents.slam.slam_map import SlamMap
from fleet.protocol import LaserScan, Odometry
from fleet.slam_params import SlamParams

WAITING = "waiting to be placed on the fleet's map"


class UnplacedSlamPose:
    """SLAM in the robot's own frame until :meth:`place`, then SLAM in the fleet's frame."""

    name = "slam"
    failed = False

    def __init__(self, params: SlamParams, range_min: float, range_max: float) -> None:
        self._params = params
        self._range = (range_min, range_max)
        self._own = SlamPose(params, (0.0, 0.0, 0.0), range_min, range_max)
        self._placed: SlamPose | None = None
        self._history: deque[Odometry] = deque(maxlen=ODOM_HISTORY)
        self._last_scan: LaserScan | None = None

    @property
    def localized(self) -> bool:
        return self._placed is not None

    @property
    def own_frame(self) -> bool:
        """Whether its pose and map are still in the robot's own frame."""
        return self._placed is None

    @property
    def reason(self) -> str:
        return "" if self._placed is not None else WAITING

    def on_odometry(self, msg: Odometry) -> None:
        if self._placed is not None:
            self._placed.on_odometry(msg)
            return
        self._own.on_odometry(msg)
        if not self._history or msg.stamp > self._history[-1].stamp:
            self._history.append(msg)

    def on_scan(self, msg: LaserScan) -> None:
        if self._placed is not None:
            self._placed.on_scan(msg)
            return
        self._own.on_scan(msg)
        self._last_scan = msg

    def place(self, x: float, y: float, theta: float) -> Pose | None:
        """Carry the robot into the fleet's frame by the transform (x, y, theta) of its own
        frame into the fleet's; its pose there, or None when it cannot be placed yet (already
        placed, or no scan mapped)."""
        if self._placed is not None or self._last_scan is None:
            return None
        # the pose at the last scan, which the fresh SLAM is given again and ties to it
        own = np.array(self._own.at_scan)
        x1, y1, th1 = compose(np.array([x, y, theta]), own)
        start = (float(x1), float(y1), float(th1))
        self._placed = SlamPose.found_at(
            self._params, start, *self._range, self._history, self._last_scan
        )
        self._history.clear()
        return start

    def pose(self) -> Pose:
        return self._own.pose() if self._placed is None else self._placed.pose()

    def covariance(self) -> np.ndarray:
        return (self._own if self._placed is None else self._placed).covariance()

    def occupancy(self) -> SlamMap | None:
        return (self._own if self._placed is None else self._placed).occupancy()
