"""Run SLAM offline over the scans of a CARMEN log and time it (no file output here)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from agents.slam.slam import Pose, Slam
from fleet.carmen import CarmenLog, LaserRecord
from fleet.slam_params import SlamParams


@dataclass(frozen=True, eq=False)
class ReplayResult:
    """``trajectory`` rows are (t, x, y, theta), each scan's pose as corrected by the final
    graph optimization; ``live`` the same rows as ``Slam.process`` returned them at the scan's
    time (what a robot drives on); ``scan_seconds`` the processing time of each scan;
    ``log_seconds`` the span of the scans' timestamps."""

    trajectory: np.ndarray
    live: np.ndarray
    scan_seconds: np.ndarray
    scan_cpu_seconds: np.ndarray
    log_seconds: float
    slam: Slam

    @property
    def speedup(self) -> float:
        """Log duration over processing time: how many times faster than real time."""
        total = float(self.scan_seconds.sum())
        return self.log_seconds / total if total > 0 else float("inf")


def replay_log(
    log: CarmenLog,
    params: SlamParams,
    range_min: float = 0.05,
    initial_pose: Pose | None = None,
    scans: Sequence[LaserRecord] | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> ReplayResult:
    """Feed every front laser record to one ``Slam``; the laser pose of each record is its
    odometry. ``scans`` replaces the log's own (e.g. the same scans with other odometry);
    ``progress(done, total)`` is called every 100 scans and at the end.

    ODOM lines are not needed: FLASER and ROBOTLASER1 carry the odometry pose at scan time. The
    map frame starts at ``initial_pose``, by default the first scan's odometry pose, so the
    trajectory is comparable with the log's own poses.
    """
    scans = list(scans) if scans is not None else log.front_scans
    if not scans:
        raise ValueError("the log holds no FLASER, RLASER or ROBOTLASER1 lines")
    start = initial_pose if initial_pose is not None else scans[0].laser_pose
    slam = Slam(
        params, start, range_min=range_min, range_max=scans[0].max_range, keep_trajectory=True
    )
    trajectory = np.empty((len(scans), 4))
    seconds = np.empty(len(scans))
    cpu = np.empty(len(scans))
    for i, rec in enumerate(scans):
        t0, c0 = time.perf_counter(), time.process_time()
        est = slam.process(
            rec.ranges, rec.angle_min, rec.angle_increment, rec.laser_pose, rec.timestamp
        )
        seconds[i] = time.perf_counter() - t0
        cpu[i] = time.process_time() - c0
        trajectory[i] = (rec.timestamp, *est.pose)
        if progress is not None and i % 100 == 99:
            progress(i + 1, len(scans))
    t0, c0 = time.perf_counter(), time.process_time()
    slam.finish()
    seconds[-1] += time.perf_counter() - t0
    cpu[-1] += time.process_time() - c0
    live = trajectory.copy()
    trajectory[:, 1:] = slam.trajectory()
    if progress is not None:
        progress(len(scans), len(scans))
    return ReplayResult(
        trajectory, live, seconds, cpu, float(scans[-1].timestamp - scans[0].timestamp), slam
    )
