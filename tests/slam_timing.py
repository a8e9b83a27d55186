"""Time SLAM on synthetic laps: ``python tests/slam_timing.py [--laps N] [--world home|ring]``.

Prints milliseconds per 360-beam scan (wall clock and process CPU time, since the machine may be
shared), the replay speed as a multiple of real time at 10 Hz, and the ATE RMSE of SLAM and of
raw odometry against the simulated truth. Scans are ray cast before the clock starts.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from slam_sim import drifting_odometry, home_segments, loop_route, ring_segments, scan

from agents.slam.slam import Slam
from fleet.slam_params import SlamParams

WORLDS = {
    "home": (home_segments, [(1.5, 1.0), (8.5, 1.0), (8.5, 5.0), (1.5, 5.0)], 0.0),
    "ring": (ring_segments, [(1.0, 1.0), (15.0, 1.0), (15.0, 9.0), (1.0, 9.0)], 0.03),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--laps", type=int, default=2)
    ap.add_argument("--world", choices=sorted(WORLDS), default="home")
    ap.add_argument(
        "--offset",
        type=float,
        default=0.0,
        help="shift world and route by this much in x and y (0.025 puts walls on cell borders)",
    )
    args = ap.parse_args()
    make, corners, scale_bias = WORLDS[args.world]
    segments = make() + args.offset
    truth = np.concatenate([loop_route(corners, 0.3, 10.0)] * args.laps)
    truth[:, :2] += args.offset
    odom = drifting_odometry(truth, 0.004, 0.02, 0.02, seed=1, scale_bias=scale_bias)
    rng = np.random.default_rng(0)
    scans = [scan(segments, pose, rng=rng) for pose in truth]
    slam = Slam(SlamParams(), tuple(truth[0]), range_min=0.1, range_max=6.0, keep_trajectory=True)
    wall = np.empty(len(truth))
    cpu = np.empty(len(truth))
    for k, (sc, od) in enumerate(zip(scans, odom, strict=True)):
        w0, c0 = time.perf_counter(), time.process_time()
        slam.process(*sc, tuple(od), 0.1 * k)
        wall[k], cpu[k] = time.perf_counter() - w0, time.process_time() - c0
    w0, c0 = time.perf_counter(), time.process_time()
    slam.finish()
    wall[-1] += time.perf_counter() - w0
    cpu[-1] += time.process_time() - c0
    err = np.hypot(*(slam.trajectory()[:, :2] - truth[:, :2]).T)
    odom_err = np.hypot(*(odom[:, :2] - truth[:, :2]).T)
    stats = slam.stats()
    print(
        json.dumps(
            {
                "world": args.world,
                "scans": len(truth),
                "route_seconds": 0.1 * len(truth),
                "ms_per_scan_median_wall": round(1000 * float(np.median(wall)), 2),
                "ms_per_scan_p95_wall": round(1000 * float(np.percentile(wall, 95)), 2),
                "ms_per_scan_median_cpu": round(1000 * float(np.median(cpu)), 2),
                "ms_per_scan_p95_cpu": round(1000 * float(np.percentile(cpu, 95)), 2),
                "replay_speedup_wall": round(0.1 * len(truth) / float(wall.sum()), 1),
                "replay_speedup_cpu": round(0.1 * len(truth) / float(cpu.sum()), 1),
                "ate_rmse_m": round(float(np.sqrt(np.mean(err**2))), 4),
                "odom_ate_rmse_m": round(float(np.sqrt(np.mean(odom_err**2))), 4),
                "loop_closures": stats.loop_closures,
                "optimizations": stats.optimizations,
            }
        )
    )


if __name__ == "__main__":
    main()
