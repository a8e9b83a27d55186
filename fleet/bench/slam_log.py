"""``fleet bench slam --log LOG``: SLAM on a real robot's log, against the log's own trajectory.

Corrected logs (such as the ACES and Freiburg 079 logs of the Radish archive) hold a reference
trajectory, a SLAM system's output, in their odometry fields and no raw odometry. The benchmark
makes odometry from the reference with the recipe of ``data/slam/README.md``, replays the scans
through the agents' SLAM on it, and scores SLAM and odometry against the reference:

1. Noisy odometry (:func:`noisy_odometry`): the reference motion between consecutive scans in
   the earlier pose's frame (dx, dy, dθ), dd = hypot(dx, dy), Gaussian noise with
   σ = 0.05·|dd| + 0.002 m on each of dx and dy and σ = 0.05·|dθ| + 0.02·dd rad on dθ,
   integrated from the first reference pose; one ``numpy.random.default_rng(seed)`` per seed.
2. Replay: :func:`agents.slam.replay.replay_log` on the log's front-laser scans with that
   odometry; per-scan wall-clock time.
3. Scores (:func:`agents.slam.evaluation.trajectory_scores`): RPE over 1, 5 and 20 scans
   (Kümmerle et al. 2009) and ATE after a rigid alignment, for the live estimate (each scan's
   pose as SLAM gave it then, what a robot drives on: the headline), the final optimised
   trajectory and the noisy odometry. Per-scan times are wall clock (``ms_per_scan_*``) and
   process CPU time (``cpu_ms_per_scan_*``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from agents.slam.evaluation import trajectory_scores
from agents.slam.geometry import compose, relative
from agents.slam.replay import replay_log
from fleet.carmen import LaserRecord, read_log
from fleet.params import FleetConfig

# The README recipe: σ_xy = TRANS_PER_M·|dd| + TRANS_FLOOR_M, σ_θ = ROT_PER_RAD·|dθ| + ROT_PER_M·dd.
TRANS_PER_M = 0.05
TRANS_FLOOR_M = 0.002
ROT_PER_RAD = 0.05
ROT_PER_M = 0.02
# The targets, on the mean over seeds: (key, bound, "max" when it must not exceed it).
LOG_TARGETS = {
    "rpe20_m": (0.10, "max"),
    "ate_m": (0.30, "max"),
    "ms_per_scan_median": (10.0, "max"),
    "ms_per_scan_p95": (15.0, "max"),
}


def noisy_odometry(reference: np.ndarray, seed: int) -> np.ndarray:
    """(N, 3) odometry poses made from (N, 3) reference poses by the recipe in the module
    docstring: noisy relative motions integrated from the first reference pose."""
    reference = np.asarray(reference, dtype=float)
    rng = np.random.default_rng(seed)
    steps = relative(reference[:-1], reference[1:])
    dd = np.hypot(steps[:, 0], steps[:, 1])
    sigma_xy = TRANS_PER_M * dd + TRANS_FLOOR_M
    sigma_theta = ROT_PER_RAD * np.abs(steps[:, 2]) + ROT_PER_M * dd
    noise = rng.standard_normal((len(steps), 3))
    noisy = steps + noise * np.column_stack([sigma_xy, sigma_xy, sigma_theta])
    out = np.empty_like(reference)
    out[0] = reference[0]
    for i, step in enumerate(noisy):
        out[i + 1] = compose(out[i], step)
    return out


def with_odometry(scans: Sequence[LaserRecord], odom: np.ndarray) -> list[LaserRecord]:
    """The scans with their laser and robot poses replaced by the rows of ``odom``."""
    return [
        replace(s, laser_pose=tuple(map(float, p)), robot_pose=tuple(map(float, p)))
        for s, p in zip(scans, odom, strict=True)
    ]


def run_log_bench(
    log_path: Path,
    cfg: FleetConfig,
    seeds: Sequence[int],
    out: Path,
    range_min: float,
    progress: Callable[[str, int, int], None] | None = None,
    every: int = 1,
) -> dict:
    """Run the benchmark for every seed; write ``out/seed-N/`` (map.png, map.yaml,
    trajectory.csv, live.csv, timing.json) and return per-seed figures and their means.

    ``every`` keeps one front-laser scan in that many (a sparse log: Freiburg 079's scans are
    0.1 m apart, every 9th is 0.9 m); the odometry is then made between the kept scans.
    ``progress(label, done, total)`` reports the replay of each seed."""
    from fleet.bench.slam_outputs import per_scan_ms, write_replay_outputs

    if every < 1:
        raise ValueError(f"every must be at least 1, got {every}")
    parsed = read_log(log_path)
    scans = parsed.front_scans[::every]
    if len(scans) < 2:
        raise ValueError(f"{log_path}: needs at least 2 laser scans, has {len(scans)}")
    reference = np.array([s.laser_pose for s in scans])
    runs = []
    for seed in seeds:
        odom = noisy_odometry(reference, seed)

        def report(done: int, total: int, seed: int = seed) -> None:
            if progress is not None:
                progress(f"seed {seed}", done, total)

        result = replay_log(
            parsed,
            cfg.slam,
            range_min=range_min,
            scans=with_odometry(scans, odom),
            progress=report,
        )
        timing = write_replay_outputs(result, parsed, out / f"seed-{seed}", cfg.slam, log_path)
        ms = result.scan_seconds * 1000.0
        cpu_ms = result.scan_cpu_seconds * 1000.0
        stats = result.slam.stats()
        runs.append(
            {
                "seed": seed,
                **trajectory_scores(result.live[:, 1:], reference),
                **trajectory_scores(result.trajectory[:, 1:], reference, prefix="final_"),
                **trajectory_scores(odom, reference, prefix="odom_"),
                **per_scan_ms(ms),
                **per_scan_ms(cpu_ms, prefix="cpu_"),
                "replay_speedup": result.speedup,
                "loop_closures": stats.loop_closures,
                "nodes": stats.nodes,
                "submaps": stats.submaps,
                "searched_share": stats.searches / max(stats.scans, 1),
                "map_png": str(Path(timing["out"]) / "map.png"),
            }
        )
    numeric = [k for k, v in runs[0].items() if isinstance(v, float) and k != "seed"]
    mean = {k: float(np.mean([r[k] for r in runs])) for k in numeric}
    mean["loop_closures"] = float(np.mean([r["loop_closures"] for r in runs]))
    return {
        "log": str(log_path),
        "scans": len(scans),
        "every": every,
        "step_m_median": float(np.median(np.hypot(*np.diff(reference[:, :2], axis=0).T))),
        "turn_deg_median": float(
            np.degrees(np.median(np.abs(relative(reference[:-1], reference[1:])[:, 2])))
        ),
        "beams": int(scans[0].ranges.size),
        "fov_deg": math.degrees(scans[0].angle_increment * scans[0].ranges.size),
        "seeds": list(seeds),
        "recipe": (
            f"sigma_xy = {TRANS_PER_M}*|dd| + {TRANS_FLOOR_M} m, "
            f"sigma_theta = {ROT_PER_RAD}*|dtheta| + {ROT_PER_M}*dd rad"
        ),
        "mean": mean,
        "runs": runs,
        "out": str(out),
    }


def bench_log(
    log_path: Path,
    cfg: FleetConfig,
    seeds: Sequence[int],
    out: Path,
    progress: Callable[[str, int, int], None] | None = None,
    every: int = 1,
) -> dict:
    """``fleet bench slam --log``: :func:`run_log_bench` with the lidar's ``range_min``, its
    result also written to ``out/bench.json``."""
    summary = run_log_bench(log_path, cfg, seeds, out, cfg.lidar.range_min, progress, every)
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary
