"""SLAM trajectory metrics (ATE, Kümmerle RPE) on hand-made trajectories, and `fleet bench slam`."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from agents.slam.evaluation import (
    align_rigid_2d,
    associate,
    ate_rmse,
    pairs_by_distance,
    pairs_by_time,
    relative_pose_error,
)
from agents.slam.geometry import compose


def square_lap(n: int = 200) -> np.ndarray:
    """Poses (t, x, y, theta) around a 4 m × 2 m rectangle, heading along the path, 10 Hz."""
    corners = np.array([(0.0, 0.0), (4.0, 0.0), (4.0, 2.0), (0.0, 2.0), (0.0, 0.0)])
    s = np.linspace(0.0, 12.0, n, endpoint=False)
    seg = np.searchsorted(np.array([4.0, 6.0, 10.0, 12.0]), s, side="right")
    start = np.array([0.0, 4.0, 6.0, 10.0])[seg]
    length = np.array([4.0, 2.0, 4.0, 2.0])[seg]
    a, b = corners[seg], corners[seg + 1]
    f = ((s - start) / length)[:, None]
    xy = a + f * (b - a)
    heading = np.arctan2(*(b - a).T[::-1])
    return np.column_stack([0.1 * np.arange(n), xy, heading])


def test_ate_of_a_constant_offset_is_its_length_and_alignment_removes_it():
    ref = square_lap()
    est = ref.copy()
    est[:, 1] += 0.03
    est[:, 2] -= 0.04
    assert ate_rmse(est, ref) == pytest.approx(0.05)
    assert ate_rmse(est, ref, align=True) == pytest.approx(0.0, abs=1e-9)


def test_ate_of_a_rotated_trajectory_and_the_rigid_alignment_recovering_it():
    ref = square_lap()
    motion = np.array([0.5, -0.2, 0.1])
    est = ref.copy()
    est[:, 1:] = compose(motion, ref[:, 1:])
    expected = np.sqrt(np.mean(np.sum((est[:, 1:3] - ref[:, 1:3]) ** 2, axis=1)))
    assert ate_rmse(est, ref) == pytest.approx(expected)
    assert expected > 0.1
    back = align_rigid_2d(est[:, 1:3], ref[:, 1:3])
    assert compose(back, motion) == pytest.approx(np.zeros(3), abs=1e-9)
    assert ate_rmse(est, ref, align=True) == pytest.approx(0.0, abs=1e-9)


def test_rpe_ignores_a_global_rigid_motion_but_ate_does_not():
    ref = square_lap()
    est = ref.copy()
    est[:, 1:] = compose(np.array([1.0, 2.0, 0.7]), ref[:, 1:])
    i, j = pairs_by_time(ref[:, 0], 1.0)
    rpe = relative_pose_error(est, ref, i, j)
    assert rpe.trans_mean == pytest.approx(0.0, abs=1e-9)
    assert rpe.rot_mean == pytest.approx(0.0, abs=1e-9)
    assert ate_rmse(est, ref) > 1.0


def test_rpe_of_a_scaled_trajectory_is_the_scale_error_of_each_step():
    """Straight line at 0.1 m per pose, estimate 10 % too long: every 1 s (10-pose) relative
    motion is 1.0 m true and 1.1 m estimated, so the translational error is 0.1 m exactly."""
    n = 50
    ref = np.column_stack([0.1 * np.arange(n), 0.1 * np.arange(n), np.zeros(n), np.zeros(n)])
    est = ref.copy()
    est[:, 1] *= 1.1
    i, j = pairs_by_time(ref[:, 0], 1.0)
    assert len(i) == n - 10
    assert np.all(j - i == 10)
    rpe = relative_pose_error(est, ref, i, j)
    assert rpe.trans_mean == pytest.approx(0.1)
    assert rpe.trans_rmse == pytest.approx(0.1)
    assert rpe.rot_mean == pytest.approx(0.0)


def test_rpe_of_a_heading_error_after_the_first_pose():
    """A heading offset of 0.05 rad on every pose from k = 20 on: pairs straddling k see a
    rotational error of 0.05 rad (and, at 1 m apart, a lateral error), the rest none."""
    n = 60
    ref = np.column_stack([0.1 * np.arange(n), 0.1 * np.arange(n), np.zeros(n), np.zeros(n)])
    est = ref.copy()
    est[20:, 3] += 0.05
    i, j = pairs_by_time(ref[:, 0], 1.0)
    straddle = (i < 20) & (j >= 20)
    rpe = relative_pose_error(est, ref, i, j)
    assert rpe.rot_mean == pytest.approx(0.05 * straddle.sum() / len(i))
    assert rpe.rot_rmse == pytest.approx(0.05 * math.sqrt(straddle.sum() / len(i)))


def test_pairs_by_distance_follow_the_reference_path():
    ref = square_lap(120)  # 0.1 m per pose
    i, j = pairs_by_distance(ref, 1.0)
    assert np.all(j - i == 10)
    assert i[-1] == len(ref) - 11


def test_associate_pairs_nearest_times_within_tolerance():
    t_ref = np.array([0.0, 0.1, 0.2, 0.3])
    est_i, ref_i = associate(np.array([0.001, 0.149, 0.21, 0.7]), t_ref, max_dt=0.06)
    assert est_i.tolist() == [0, 1, 2]
    assert ref_i.tolist() == [0, 1, 2]


def test_mismatched_trajectories_are_refused():
    ref = square_lap()
    with pytest.raises(ValueError, match="equally many"):
        ate_rmse(ref[:-1], ref)
    with pytest.raises(ValueError, match="no pose pairs"):
        relative_pose_error(ref[:5], ref[:5], *pairs_by_time(ref[:5, 0], 10.0))


BENCH_KEYS = {
    "ate_rmse_m",
    "odom_ate_rmse_m",
    "rpe_trans_m",
    "rpe_rot_deg",
    "ms_per_scan_median",
    "ms_per_scan_p95",
    "replay_speedup",
}


def test_fleet_bench_slam_short_route_beats_odometry_and_keeps_its_files(tmp_path):
    from fleet.cli import app

    out = tmp_path / "bench"
    result = CliRunner().invoke(
        app, ["bench", "slam", "--seconds", "40", "--json", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout.strip().splitlines()[-1])
    assert summary.keys() >= BENCH_KEYS
    assert summary["scans"] == 400
    assert summary["wall_collisions"] == 0
    assert summary["path_length_m"] > 4.0
    assert summary["ate_rmse_m"] < summary["odom_ate_rmse_m"]
    assert summary["ate_rmse_m"] < 0.05
    assert summary["rpe_rot_deg"] < summary["odom_rpe_rot_deg"]
    for name in ("slam.log", "slam.log.truth.csv", "map.png", "trajectory.csv", "bench.json"):
        assert (out / name).is_file(), name


def test_fleet_bench_slam_refuses_bad_options():
    from fleet.cli import app

    result = CliRunner().invoke(app, ["bench", "slam", "--seconds", "1"])
    assert result.exit_code == 2
    result = CliRunner().invoke(app, ["bench", "slam", "--world", "no-such-world"])
    assert result.exit_code == 2
    assert "no-such-world" in result.output


def test_shift_world_moves_every_part_of_the_world():
    from fleet.config import resolve_world
    from fleet.world import load_world, shift_world

    world = load_world(resolve_world("home"))
    moved = shift_world(world, 0.025, -0.01)
    for a, b in zip(world.polygons, moved.polygons, strict=True):
        np.testing.assert_allclose(b - a, np.broadcast_to([0.025, -0.01], a.shape))
    assert moved.bounds == pytest.approx(np.add(world.bounds, [0.025, -0.01, 0.025, -0.01]))
    np.testing.assert_allclose(
        [s[:2] for s in moved.starts], [(x + 0.025, y - 0.01) for x, y, _ in world.starts]
    )
    if world.dock is not None:
        assert moved.dock == pytest.approx(
            (world.dock[0] + 0.025, world.dock[1] - 0.01, world.dock[2])
        )
    assert moved.start_poses(1, 0.17)[0][:2] == pytest.approx(
        (world.start_poses(1, 0.17)[0][0] + 0.025, world.start_poses(1, 0.17)[0][1] - 0.01)
    )
