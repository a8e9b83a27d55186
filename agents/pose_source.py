"""Where the agent believes it is. One small interface, so SLAM can replace odometry.

A control step feeds its pose source the scan and reads where the robot is (:func:`locate`).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from agents.slam.geometry import compose, relative
from agents.slam.matcher import LikelihoodField
from agents.slam.persistence import SavedState
from agents.slam.relocalize import map_field, relocalize
from agents.slam.slam import Slam
from agents.slam.slam_map import SlamMap
from agents.slam.submaps import map_lattice
from fleet.protocol import LaserScan, Odometry
from fleet.slam_params import SlamParams

Pose = tuple[float, float, float]


ODOM_HISTORY = 64


class PoseSource(Protocol):
    """Fed with odometry and scans; answers the current pose estimate and its covariance."""

    name: str

    @property
    def localized(self) -> bool:
        """Whether it knows where the robot is (a respawned robot's may not yet)."""
        ...

    @property
    def failed(self) -> bool:
        """Whether it has given up finding the robot for now."""
        ...

    @property
    def reason(self) -> str:
        """Why it is not localized; "" once it is."""
        ...

    @property
    def own_frame(self) -> bool:
        """Whether its pose and map are in the robot's own frame, not the fleet's (a robot
        started with no known pose, not yet placed: ``agents.placing``)."""
        ...

    def on_odometry(self, msg: Odometry) -> None: ...

    def on_scan(self, msg: LaserScan) -> None: ...

    def pose(self) -> Pose: ...

    def covariance(self) -> np.ndarray: ...

    def occupancy(self) -> SlamMap | None: ...


class OdometryPose:
    """Dead reckoning: the odometry pose, which starts at the spawn pose (as the dock is known)."""

    name = "odometry"
    localized = True
    failed = False
    reason = ""
    own_frame = False

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


@dataclass(frozen=True, eq=False)
class Located:
    """What a pose source says after a scan: the pose and its covariance (row-major 3×3), the
    source's name, and whether it knows where the robot is (see :class:`PoseSource`)."""

    pose: Pose
    covariance: np.ndarray
    source: str
    localized: bool
    failed: bool
    reason: str


def locate(source: PoseSource, scan: LaserScan) -> Located:
    """Feed ``source`` the scan and say where the robot is."""
    source.on_scan(scan)
    return Located(
        source.pose(),
        source.covariance(),
        source.name,
        source.localized,
        source.failed,
        source.reason,
    )


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
    localized = True
    failed = False
    reason = ""
    own_frame = False

    def __init__(
        self,
        params: SlamParams,
        start: Pose,
        range_min: float,
        range_max: float,
        lattice: tuple[float, float] | None = None,
    ) -> None:
        self._slam = Slam(params, start, range_min=range_min, range_max=range_max, lattice=lattice)
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

    @classmethod
    def found_at(
        cls,
        params: SlamParams,
        start: Pose,
        range_min: float,
        range_max: float,
        history: Sequence[Odometry],
        scan: LaserScan,
        lattice: tuple[float, float] | None = None,
    ) -> SlamPose:
        """SLAM started at ``start``, the pose at ``scan``'s stamp, and given the recent
        odometry and that scan: its pose is tied to the odometry at the scan's stamp, and later
        odometry increments apply from there (a robot found in its saved map, or placed on the
        fleet's). ``lattice``: the map's cell boundaries (``Slam``), e.g. the saved map's."""
        slam = cls(params, start, range_min, range_max, lattice)
        for odom in history:
            slam.on_odometry(odom)
        slam.on_scan(scan)
        return slam

    @property
    def at_scan(self) -> Pose:
        """The estimate at the last scan's stamp (the start pose before any scan)."""
        return self._at_scan

    def pose(self) -> Pose:
        if self._odom is None or self._odom_at_scan is None:
            return self._at_scan
        x, y, theta = compose(self._at_scan, relative(self._odom_at_scan, self._odom))
        return (float(x), float(y), float(theta))

    def covariance(self) -> np.ndarray:
        return self._covariance.copy()

    def occupancy(self) -> SlamMap | None:
        return self._slam.occupancy()


class RelocalizingSlamPose:
    """SLAM for a restarted agent: first find the robot in its saved map, then track as usual.

    Until localized, each scan (paired with odometry) is matched against the saved map
    (``agents.slam.relocalize``) around the saved pose: first within ``near`` (± metres,
    ± radians: how far the body can have moved since that pose was saved, see
    ``respawn_window``), then, if that finds nothing, within the wide ``reloc_window_xy`` and
    ``reloc_window_theta`` (a body pushed or carried away). After ``reloc_max_scans`` failed
    attempts the source is ``failed`` with the last reason, and tries again only on every
    ``reloc_max_scans``-th scan (peers that stood in view may have left). Meanwhile ``pose()``
    is the saved pose with the wide window as its covariance, and the agent must not drive.
    Once a scan matches, a fresh ``SlamPose`` starts at the found pose and is given the recent
    odometry and that scan, so its pose is tied to the odometry at the scan's stamp and later
    odometry increments apply from there.

    ``occupancy()`` is the saved map, and once localized the new SLAM's map laid over it (a cell
    the new SLAM has observed replaces the saved one), so the map saved next still holds what was
    known before the restart.
    """

    name = "slam"
    own_frame = False

    def __init__(
        self,
        params: SlamParams,
        saved: SavedState,
        range_min: float,
        range_max: float,
        near: tuple[float, float] | None = None,
    ) -> None:
        self._params = params
        self._saved = saved
        self._near = near
        self._range_min = range_min
        self._range_max = range_max
        self._field: LikelihoodField | None = None
        self._history: deque[Odometry] = deque(maxlen=ODOM_HISTORY)
        self._slam: SlamPose | None = None
        self._scans = 0
        self._attempts = 0
        self._failed = False
        self._reason = "no scan with odometry yet"

    @property
    def localized(self) -> bool:
        return self._slam is not None

    @property
    def failed(self) -> bool:
        return self._failed

    @property
    def reason(self) -> str:
        """Why the source is not localized (the last attempt's reason); "" once it is."""
        return self._reason

    def on_odometry(self, msg: Odometry) -> None:
        if self._slam is not None:
            self._slam.on_odometry(msg)
        elif not self._history or msg.stamp > self._history[-1].stamp:
            self._history.append(msg)

    def on_scan(self, msg: LaserScan) -> None:
        if self._slam is not None:
            self._slam.on_scan(msg)
            return
        p = self._params
        if not self._history:
            return
        self._scans += 1
        if self._failed and self._scans % p.reloc_max_scans:
            return
        if self._field is None:
            self._field = map_field(self._saved.occupancy, p)
        self._attempts += 1
        windows = {"wide": (p.reloc_window_xy, p.reloc_window_theta)}
        if self._near is not None:
            windows = {"near": self._near, **windows}
        reasons = []
        for name, (window_xy, window_theta) in windows.items():
            result = relocalize(
                self._saved.occupancy,
                p,
                msg.ranges.astype(np.float64),
                msg.angle_min,
                msg.angle_increment,
                self._saved.pose,
                window_xy,
                window_theta,
                self._range_min,
                self._range_max,
                field=self._field,
            )
            if result.ok:
                break
            reasons.append(f"{name}: {result.reason}")
        if not result.ok:
            self._reason = f"attempt {self._attempts}: {'; '.join(reasons)}"
            self._failed = self._attempts >= p.reloc_max_scans
            return
        saved = self._saved.occupancy
        self._slam = SlamPose.found_at(
            p,
            result.pose,
            self._range_min,
            self._range_max,
            self._history,
            msg,
            # on the saved map's lattice, so the new map can be laid over it (overlay)
            tuple(map_lattice(saved.origin, saved.resolution)),
        )
        self._field = None
        self._reason = ""

    def pose(self) -> Pose:
        return self._saved.pose if self._slam is None else self._slam.pose()

    def covariance(self) -> np.ndarray:
        if self._slam is not None:
            return self._slam.covariance()
        p = self._params
        return np.diag(
            [p.reloc_window_xy**2, p.reloc_window_xy**2, p.reloc_window_theta**2]
        ).reshape(9)

    def occupancy(self) -> SlamMap | None:
        saved = self._saved.occupancy
        if self._slam is None:
            return saved
        fresh = self._slam.occupancy()
        return overlay(saved, fresh) if fresh is not None else saved


def overlay(base: SlamMap, top: SlamMap) -> SlamMap:
    """``top`` laid over ``base`` on the union of their extents: cells ``top`` observed (non-zero
    log-odds) take its value, the others keep ``base``'s. Both must share resolution and cell
    lattice (maps of ``Slam`` do, and their tile-snapped bounds stay tile-snapped); otherwise the
    result is ``top`` alone."""
    res = top.resolution
    shift = (np.asarray(base.origin) - np.asarray(top.origin)) / res
    cells = np.rint(shift)
    if base.resolution != res or np.abs(shift - cells).max() > 1e-3:
        return top
    b_r, b_c = int(cells[1]), int(cells[0])  # base's first cell in top's cell indices
    r0, c0 = min(0, b_r), min(0, b_c)
    r1 = max(top.shape[0], b_r + base.shape[0])
    c1 = max(top.shape[1], b_c + base.shape[1])
    out = np.zeros((r1 - r0, c1 - c0), dtype=np.float32)
    out[b_r - r0 : b_r - r0 + base.shape[0], b_c - c0 : b_c - c0 + base.shape[1]] = base.log_odds
    block = out[-r0 : -r0 + top.shape[0], -c0 : -c0 + top.shape[1]]
    seen = top.log_odds != 0
    block[seen] = top.log_odds[seen]
    origin = (top.origin[0] + c0 * res, top.origin[1] + r0 * res)
    return SlamMap(out, res, origin)
