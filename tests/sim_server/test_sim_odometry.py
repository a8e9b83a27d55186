"""Odometry drift statistics against the truth they were generated from.

Each statistical test drives the same scripted path with M robots at once (one model, one
generator: M independent noise sequences) and compares the spread of the final errors with what
the model predicts. With M = 4000 the sample std is within ±5 % of the truth with probability
> 0.9999, and sample means are compared within 4.5 standard errors.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fleet.params import OdometryParams
from sim_server.odometry import OdometryModel, decompose_motion, wrap_angle

M = 4000
STD_TOL = 0.05


def drive(params: OdometryParams, path: np.ndarray, seed: int = 0, robots: int = M) -> np.ndarray:
    """Run M robots along the same true path (T, 3); returns the final odometry poses (M, 3)."""
    model = OdometryModel(params, np.random.default_rng(seed), np.tile(path[0], (robots, 1)))
    for pose in path[1:]:
        odom = model.update(np.tile(pose, (robots, 1)))
    return odom


def straight(distance: float, steps: int, heading: float = 0.3, sign: float = 1.0) -> np.ndarray:
    s = np.linspace(0.0, distance, steps + 1) * sign
    return np.column_stack(
        [1.0 + s * math.cos(heading), -2.0 + s * math.sin(heading), np.full(steps + 1, heading)]
    )


def assert_std(samples: np.ndarray, expected: float) -> None:
    assert abs(samples.std() / expected - 1) < STD_TOL, (samples.std(), expected)


def assert_mean(samples: np.ndarray, expected: float, std: float) -> None:
    assert abs(samples.mean() - expected) < 4.5 * std / math.sqrt(samples.size), (
        samples.mean(),
        expected,
    )


def test_without_noise_odometry_equals_truth():
    params = OdometryParams(
        alpha_trans=0, alpha_rot=0, alpha_rot_trans=0, alpha_trans_rot=0, heading_bias_per_m=0
    )
    rng = np.random.default_rng(1)
    t = np.linspace(0, 20, 1001)
    # A wiggly path with forward and backward driving and turns in place.
    path = np.column_stack([np.sin(t) * 2, np.cos(0.7 * t), wrap_angle(0.9 * t + np.sin(3 * t))])
    path[500:520, :2] = path[500, :2]
    model = OdometryModel(params, rng, path[0])
    for pose in path[1:]:
        odom = model.update(pose)
        np.testing.assert_allclose(odom[:2], pose[:2], rtol=0, atol=1e-9)
        assert abs(wrap_angle(odom[2] - pose[2])) < 1e-9


def test_bias_alone_turns_the_heading_by_bias_times_signed_distance():
    bias = 0.004
    params = OdometryParams(
        alpha_trans=0, alpha_rot=0, alpha_rot_trans=0, alpha_trans_rot=0, heading_bias_per_m=bias
    )
    forward = drive(params, straight(10.0, 500), robots=1)[0]
    assert abs(wrap_angle(forward[2] - 0.3) - bias * 10.0) < 1e-12
    backward = drive(params, straight(4.0, 200, sign=-1.0), robots=1)[0]
    assert abs(wrap_angle(backward[2] - 0.3) + bias * 4.0) < 1e-12
    # Turning in place does not drift.
    turn = np.column_stack([np.zeros(50), np.zeros(50), np.linspace(0, 3, 50)])
    assert abs(drive(params, turn, robots=1)[0, 2] - 3.0) < 1e-12
    # The heading error builds up as the robot drives, so the path curves: lateral ≈ b·D²/2.
    s, c = math.sin(-0.3), math.cos(-0.3)
    lateral = s * (forward[0] - 1.0) + c * (forward[1] + 2.0)
    assert lateral == pytest.approx(bias * 10.0**2 / 2, rel=1e-3)


@pytest.mark.parametrize("steps", [200, 800])
def test_straight_drive_drift_matches_the_random_walk_prediction(steps):
    params = OdometryParams(
        alpha_trans=0.02,
        alpha_rot=0.05,
        alpha_rot_trans=0.01,
        alpha_trans_rot=0.01,
        heading_bias_per_m=0.004,
    )
    distance, heading = 10.0, 0.3
    final = drive(params, straight(distance, steps, heading))
    ds = distance / steps
    heading_err = wrap_angle(final[:, 2] - heading)
    # Heading: 2·steps independent half-step terms of variance ½·α²·ds, plus the bias.
    heading_sd = params.alpha_trans_rot * math.sqrt(distance)
    assert_std(heading_err, heading_sd)
    assert_mean(heading_err, params.heading_bias_per_m * distance, heading_sd)
    # Errors in the path's frame: along-track and lateral.
    ex, ey = (
        final[:, 0] - (1.0 + distance * math.cos(heading)),
        final[:, 1] - (-2.0 + distance * math.sin(heading)),
    )
    along = ex * math.cos(heading) + ey * math.sin(heading)
    lateral = -ex * math.sin(heading) + ey * math.cos(heading)
    # Lateral = Σ_k ds·φ_k (small angles), φ_k the heading error while step k translates:
    # rot1 noise of step j acts on (steps − j) translations, rot2 noise on (steps − j − 1).
    v = 0.5 * params.alpha_trans_rot**2 * ds
    i = np.arange(steps + 1)
    lateral_sd = ds * math.sqrt(v * (np.sum(i[1:] ** 2) + np.sum(i[:-1] ** 2)))
    assert lateral_sd == pytest.approx(
        params.alpha_trans_rot * math.sqrt(distance**3 / 3), rel=0.02
    )
    assert_std(lateral, lateral_sd)
    mean_phi = params.heading_bias_per_m * ds * (np.arange(steps) + 0.5)
    assert_mean(lateral, ds * np.sum(np.sin(mean_phi)), lateral_sd)
    along_sd = params.alpha_trans * math.sqrt(distance)
    assert_std(along, along_sd)
    # Second order: the heading error shortens the along-track progress by ds·φ²/2 per step.
    var_phi = v * (2 * np.arange(steps) + 1)
    assert_mean(along, -0.5 * ds * np.sum(var_phi + mean_phi**2), along_sd)


def test_drift_does_not_depend_on_the_odometry_rate():
    params = OdometryParams()
    slow = drive(params, straight(5.0, 100), seed=3)
    fast = drive(params, straight(5.0, 1000), seed=4)
    for k in range(3):
        assert abs(slow[:, k].std() / fast[:, k].std() - 1) < 2 * STD_TOL


def test_turn_in_place_drift_matches_prediction_despite_physics_jitter():
    params = OdometryParams(
        alpha_trans=0.02,
        alpha_rot=0.03,
        alpha_rot_trans=0.01,
        alpha_trans_rot=0.01,
        heading_bias_per_m=0.004,
    )
    steps, total_turn = 300, 2 * math.pi
    theta = np.linspace(0.0, total_turn, steps + 1)
    jitter = np.random.default_rng(9).normal(0.0, 1e-6, size=(steps + 1, 2))
    path = np.column_stack([0.5 + jitter[:, 0], 0.5 + jitter[:, 1], wrap_angle(theta)])
    final = drive(params, path)
    heading_err = wrap_angle(final[:, 2] - path[-1, 2])
    heading_sd = params.alpha_rot * math.sqrt(total_turn)
    assert_std(heading_err, heading_sd)
    assert_mean(heading_err, 0.0, heading_sd)
    # Translation noise per radian turned: E|position error|² = α_rot_trans²·Θ.
    sq = (final[:, 0] - path[-1, 0]) ** 2 + (final[:, 1] - path[-1, 1]) ** 2
    assert math.sqrt(sq.mean()) == pytest.approx(
        params.alpha_rot_trans * math.sqrt(total_turn), rel=STD_TOL
    )


def test_arc_heading_drift_adds_rotation_and_distance_terms():
    params = OdometryParams(
        alpha_trans=0.02,
        alpha_rot=0.03,
        alpha_rot_trans=0.01,
        alpha_trans_rot=0.02,
        heading_bias_per_m=0.0,
    )
    radius, sweep, steps = 1.5, math.pi, 400
    a = np.linspace(0.0, sweep, steps + 1)
    path = np.column_stack([radius * np.sin(a), radius * (1 - np.cos(a)), wrap_angle(a)])
    final = drive(params, path)
    heading_err = wrap_angle(final[:, 2] - path[-1, 2])
    expected = math.sqrt(params.alpha_rot**2 * sweep + params.alpha_trans_rot**2 * radius * sweep)
    assert_std(heading_err, expected)


def test_reversing_is_a_negative_translation_not_a_half_turn():
    rot1, trans, rot2 = decompose_motion(
        np.array([0.0, 0.0, 0.2]), np.array([-0.098, -0.0199, 0.21])
    )
    assert abs(rot1) < 0.01 and trans < 0 and abs(rot1 + rot2 - 0.01) < 1e-12
    params = OdometryParams(
        alpha_trans=0.02,
        alpha_rot=0.2,
        alpha_rot_trans=0.01,
        alpha_trans_rot=0.01,
        heading_bias_per_m=0.0,
    )
    final = drive(params, straight(4.0, 200, sign=-1.0))
    assert_std(wrap_angle(final[:, 2] - 0.3), params.alpha_trans_rot * 2.0)


def test_seeds_reproduce_and_differ():
    params = OdometryParams()
    path = straight(2.0, 50)
    a, b = drive(params, path, seed=5, robots=3), drive(params, path, seed=5, robots=3)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, drive(params, path, seed=6, robots=3))


def test_shape_mismatch_is_an_error():
    model = OdometryModel(OdometryParams(), np.random.default_rng(0), (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="shape"):
        model.update(np.zeros((2, 3)))


def test_robots_joining_and_leaving_a_batch_draw_the_noise_single_models_would():
    params = OdometryParams(alpha_trans=0.02, alpha_rot=0.05, alpha_rot_trans=0.01)
    path = straight(1.0, 30)
    shifts = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [0.0, 0.5, 0.0]])
    batch_rng, single_rng = np.random.default_rng(9), np.random.default_rng(9)
    batch = OdometryModel(params, batch_rng, np.zeros((0, 3)))
    singles: dict[int, OdometryModel] = {}
    for k, pose in enumerate(path):
        if k in (0, 10):  # robots 0 and 1 join first, robot 2 at step 10
            for r in (0, 1) if k == 0 else (2,):
                batch.add(pose + shifts[r])
                singles[r] = OdometryModel(params, single_rng, pose + shifts[r])
            continue
        if k == 20:  # robot 0 leaves; robots 1 and 2 move up a row
            batch.remove(0)
            del singles[0]
        rows = sorted(singles)
        got = batch.update(np.array([pose + shifts[r] for r in rows]))
        want = np.array([singles[r].update(pose + shifts[r]) for r in rows])
        np.testing.assert_array_equal(got, want)
    assert not np.allclose(got[:, :2], path[-1, :2] + shifts[[1, 2], :2], atol=1e-4)


def test_a_single_robot_model_has_no_rows_to_add():
    model = OdometryModel(OdometryParams(), np.random.default_rng(0), (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="N, 3"):
        model.add((1.0, 0.0, 0.0))
