"""Record one simulated robot's scans and odometry as a CARMEN log, its true poses beside it.

Used by ``fleet sim --record-carmen FILE`` and by ``fleet bench slam``. The log holds one
``ROBOTLASER1`` line per scan (it carries its own angles, so a 360° scan needs no ``PARAM``
lines; laser and robot pose are both the odometry pose at the scan, as the lidar sits at the
robot's centre) and one ``ODOM`` line per odometry message; no-returns are written as the
scanner's maximum range, the CARMEN convention. Timestamps are sim seconds. The formatting
itself is :mod:`fleet.carmen`'s, so ``read_log`` and ``fleet slam replay`` read it back.

``FILE.truth.csv`` (header ``t,x,y,theta``) holds the true pose at every recorded scan, with the
scan's timestamp. Only the truth side of the simulator may write it: agents never see it.

One robot per log: the one named, else the first robot that spawns. Both files are flushed
after every scan, so a process stopped by a signal loses at most the odometry lines since the
last scan (a ``.gz`` log is only complete after :meth:`CarmenRecorder.close`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from types import TracebackType

import numpy as np

from fleet.carmen import format_odom, format_robotlaser1, open_text
from fleet.protocol import LaserScan, Odometry

Pose = tuple[float, float, float]
HOSTNAME = "fleet-sim"


def truth_path_for(log_path: str | Path) -> Path:
    """The truth side file of a log: ``FILE.truth.csv``."""
    p = Path(log_path)
    return p.with_name(p.name + ".truth.csv")


class CarmenRecorder:
    """Writes a CARMEN log of one robot and the matching truth file; see the module docstring.

    Call :meth:`record` after every simulator step with the step's odometry and scan messages;
    ``truth`` is called (only when the robot's scan is due) for the true poses by robot id.
    """

    def __init__(self, path: str | Path, robot: str | None = None, comment: str = "") -> None:
        self.path = Path(path)
        self.truth_path = truth_path_for(self.path)
        self.robot = robot
        self.scans = 0
        self.odometry = 0
        self.skipped_scans = 0
        self._odom: Odometry | None = None
        self._log = open_text(self.path, "w")
        try:
            self._truth = open(self.truth_path, "w", encoding="utf-8")  # noqa: SIM115 (closed in close())
        except OSError:
            self._log.close()
            raise
        self._log.write("# CARMEN log written by fleet sim: ROBOTLASER1 and ODOM, sim time\n")
        if comment:
            self._log.write(f"# {comment}\n")
        self._truth.write("t,x,y,theta\n")
        self.flush()

    def record(
        self,
        odometry: Iterable[tuple[str, Odometry]],
        scans: Iterable[tuple[str, LaserScan]],
        truth: Callable[[], Mapping[str, Pose]],
    ) -> None:
        """Write the recorded robot's messages of one step (odometry first, as the sim computes
        it first). A scan before the robot's first odometry is skipped and counted."""
        for rid, odom in odometry:
            if self.robot is None:
                self.robot = rid
            if rid == self.robot:
                self._odom = odom
                self.odometry += 1
                self._log.write(
                    format_odom(
                        (odom.x, odom.y, odom.theta),
                        odom.v,
                        odom.w,
                        0.0,
                        odom.stamp,
                        HOSTNAME,
                        odom.stamp,
                    )
                    + "\n"
                )
        for rid, scan in scans:
            if self.robot is None:
                self.robot = rid
            if rid != self.robot:
                continue
            if self._odom is None:
                self.skipped_scans += 1
                continue
            self._write_scan(scan, self._odom, truth()[rid])

    def _write_scan(self, scan: LaserScan, odom: Odometry, true_pose: Pose) -> None:
        # CARMEN has no inf: no return is the range's maximum, too near is 0
        ranges = np.where(np.isfinite(scan.ranges), scan.ranges, scan.range_max)
        ranges = np.where(scan.ranges == -np.inf, 0.0, ranges)
        pose = (odom.x, odom.y, odom.theta)
        x, y, theta = true_pose
        self._truth.write(f"{scan.stamp:.6f},{x:.6f},{y:.6f},{theta:.6f}\n")
        self._log.write(
            format_robotlaser1(
                ranges,
                scan.angle_min,
                scan.angle_increment,
                scan.range_max,
                pose,
                pose,
                scan.stamp,
                HOSTNAME,
                scan.stamp,
                odom.v,
                odom.w,
            )
            + "\n"
        )
        self.scans += 1
        self.flush()

    def flush(self) -> None:
        self._truth.flush()
        self._log.flush()

    def close(self) -> None:
        self._log.close()
        self._truth.close()

    def __enter__(self) -> CarmenRecorder:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def read_truth(path: str | Path) -> np.ndarray:
    """Rows (t, x, y, theta) of a truth file written by :class:`CarmenRecorder`."""
    p = Path(path)
    with open(p, encoding="utf-8") as f:
        header = f.readline().strip()
    if header != "t,x,y,theta":
        raise ValueError(f"{p}:1: expected the header 't,x,y,theta', got {header!r}")
    return np.loadtxt(p, delimiter=",", skiprows=1, ndmin=2).reshape(-1, 4)
