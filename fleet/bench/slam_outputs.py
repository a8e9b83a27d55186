"""What a SLAM replay of a log leaves behind: its trajectories, map and timing as files, and
its scores against a truth file. Shared by `fleet slam replay` and the SLAM benchmarks
(fleet.bench.slam, fleet.bench.slam_log)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def score_against_truth(result, parsed, truth_file: Path) -> dict:
    """Scores of the live and final trajectories and of the log's odometry against a truth file
    (rows t, x, y, theta; each scan paired with the truth row of its timestamp)."""
    from agents.slam.evaluation import associate, trajectory_scores
    from sim_server.recorder import read_truth

    truth = read_truth(truth_file)
    est_i, ref_i = associate(result.trajectory[:, 0], truth[:, 0], max_dt=1e-3)
    if len(est_i) != len(result.trajectory):
        missing = len(result.trajectory) - len(est_i)
        raise ValueError(f"{truth_file}: {missing} scans have no truth row at their time")
    ref = truth[ref_i]
    odom = np.array([s.laser_pose for s in parsed.front_scans])[est_i]
    return {
        "truth": str(truth_file),
        **trajectory_scores(result.live[est_i], ref),
        **trajectory_scores(result.trajectory[est_i], ref, prefix="final_"),
        **trajectory_scores(odom, ref[:, 1:], prefix="odom_"),
    }


def write_replay_outputs(result, parsed, out: Path, params, log: Path) -> dict:
    """Write a replay's trajectory.csv, live.csv, map.png with map.yaml (ROS map_server
    colours, thresholds from ``params``) and timing.json into ``out``; returns the summary
    that timing.json holds."""
    from PIL import Image

    out.mkdir(parents=True, exist_ok=True)
    np.savetxt(
        out / "trajectory.csv",
        result.trajectory,
        delimiter=",",
        header="t,x,y,theta",
        comments="",
        fmt=["%.6f", "%.4f", "%.4f", "%.5f"],
    )
    np.savetxt(
        out / "live.csv",
        result.live,
        delimiter=",",
        header="t,x,y,theta",
        comments="",
        fmt=["%.6f", "%.4f", "%.4f", "%.5f"],
    )
    slam_map = result.slam.occupancy()
    p = slam_map.probabilities()
    image = np.full(p.shape, 205, dtype=np.uint8)
    image[p >= params.occupied_threshold] = 0
    image[p <= params.free_threshold] = 254
    Image.fromarray(image[::-1]).save(out / "map.png")
    (out / "map.yaml").write_text(
        "image: map.png\n"
        f"resolution: {slam_map.resolution}\n"
        f"origin: [{slam_map.origin[0]}, {slam_map.origin[1]}, 0.0]\n"
        "negate: 0\n"
        f"occupied_thresh: {params.occupied_threshold}\n"
        f"free_thresh: {params.free_threshold}\n"
    )
    ms = result.scan_seconds * 1000.0
    stats = result.slam.stats()
    summary = {
        "log": str(log),
        "scans": int(ms.size),
        "log_seconds": result.log_seconds,
        "processing_seconds": float(result.scan_seconds.sum()),
        **per_scan_ms(ms),
        "replay_speedup": result.speedup,
        "nodes": stats.nodes,
        "submaps": stats.submaps,
        "loop_closures": stats.loop_closures,
        "optimizations": stats.optimizations,
        "skipped_messages": dict(parsed.skipped),
        "truncated_line": parsed.truncated_line,
        "out": str(out),
    }
    (out / "timing.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def per_scan_ms(ms: np.ndarray, prefix: str = "") -> dict[str, float]:
    """Median, p95 and max of per-scan times in milliseconds, as ``<prefix>ms_per_scan_*``."""
    return {
        f"{prefix}ms_per_scan_median": float(np.median(ms)),
        f"{prefix}ms_per_scan_p95": float(np.percentile(ms, 95)),
        f"{prefix}ms_per_scan_max": float(ms.max()),
    }
