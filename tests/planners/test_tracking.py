"""The tracker's pure parts: the braking profile, the stop speed, the turn rate, Samson's law."""

from __future__ import annotations

import math

import numpy as np
import pytest
from robots import ROBOT

from planners.tracking import (
    Frenet,
    Profile,
    TrackerParams,
    samson_turn_rate,
    track_speed,
    turn_rate,
    turn_time,
)

PARAMS = TrackerParams()
STOP = math.radians(45)


def test_a_boustrophedon_stops_at_its_corners_and_runs_its_lanes_at_full_speed() -> None:
    path = np.array([[0, 0], [3, 0], [3, 0.25], [0, 0.25]], dtype=float)
    profile = Profile.of(path, 0, STOP, 0.015, PARAMS, ROBOT)
    assert profile.kept.tolist() == [0, 1, 2, 3]
    assert profile.speeds[[0, 1, 2, 3]].tolist() == [0.0, 0.0, 0.0, 0.0]
    assert [profile.is_stop(i) for i in range(4)] == [True] * 4


def test_a_gentle_corner_is_rounded_and_driven_through_below_its_limits() -> None:
    path = np.array([[0, 0], [2, 0], [4, 0.5]], dtype=float)
    profile = Profile.of(path, 0, STOP, 0.015, PARAMS, ROBOT)
    r, v = profile.radii[1], profile.speeds[1]
    turn = math.atan2(0.5, 2)
    assert r > 0 and 0 < v <= min(ROBOT.max_vel_x, ROBOT.max_vel_theta * r)
    assert v <= 2 * r * math.tan(turn / 2) / float(turn_time(np.array(turn), ROBOT)) + 1e-9
    # the arc passes no farther than corner_deviation from the vertex
    assert r * (1 / math.cos(turn / 2) - 1) <= PARAMS.corner_deviation + 1e-9


def test_a_staircase_of_grid_steps_is_tracked_as_one_line() -> None:
    """Steps of 2.5 cm lie 1.8 cm off their diagonal: within a 2 cm simplification."""
    steps = [[0.025 * (k // 2 + k % 2), 0.025 * (k // 2)] for k in range(21)]
    profile = Profile.of(np.array(steps, dtype=float), 0, STOP, 0.02, PARAMS, ROBOT)
    assert profile.kept.tolist() == [0, 20]
    assert profile.segment[1:].tolist() == [1] * 20


def test_a_lane_is_tracked_on_its_own_line_not_on_a_chord_that_skips_its_start() -> None:
    """Home's lane under the bed, as the plan gave it: a lane down the bed's side, a chamfer
    round its corner, the 1.5 m lane along its foot. Its start lies 2.5 cm from the chord
    from the chamfer's middle to its end: plain RDP (3 cm) dropped it, and the lane was driven
    on a slant, 1.2 cm nearer the bed at its middle, which the tracker's check then refused."""
    path = np.array(
        [[1.8875, 6.2375], [1.8875, 4.3625], [1.8375, 4.2625], [1.7375, 4.2375], [0.2375, 4.2375]]
    )
    profile = Profile.of(path, 0, STOP, 0.03, PARAMS, ROBOT)
    assert {1, 3, 4} <= set(profile.kept.tolist())
    # every stretch of the simplified path lies on the lane where the lane is
    simple = path[profile.kept]
    k = profile.segment[4]
    assert np.allclose(simple[k - 1 : k + 1], path[3:5])


def test_the_stop_speed_brakes_onto_the_stop_within_the_acceleration_limit() -> None:
    """Driven by its own commands through a velocity ramp at acc_lim_x, the robot comes to
    rest within stop_tolerance of the stop, never past it, from full speed."""
    dt, h = 0.1, 0.01
    x, v, length = 0.0, ROBOT.max_vel_x, 2.0
    for _ in range(400):
        cmd = track_speed(length - x, 0.0, 0.0, v, dt, PARAMS, ROBOT)
        for _ in range(int(dt / h)):
            v += float(np.clip(cmd - v, -ROBOT.acc_lim_x * h, ROBOT.acc_lim_x * h))
            x += v * h
        assert x <= length + 1e-3
        if length - x <= PARAMS.stop_tolerance and v < 1e-3:
            break
    assert length - x <= PARAMS.stop_tolerance and v < 1e-3


def test_the_turn_in_place_lands_on_its_heading() -> None:
    dt, h = 0.1, 0.01
    heading, w = 0.0, 0.0
    for _ in range(100):
        cmd = turn_rate(math.pi / 2 - heading, w, dt, ROBOT)
        for _ in range(int(dt / h)):
            w += float(np.clip(cmd - w, -ROBOT.acc_lim_theta * h, ROBOT.acc_lim_theta * h))
            heading += w * h
    assert abs(heading - math.pi / 2) < PARAMS.heading_tolerance and abs(w) < 0.05


def test_samson_steers_back_onto_the_line() -> None:
    left_of = Frenet(0.0, 0.05, 0.0, 1.0)
    right_of = Frenet(0.0, -0.05, 0.0, 1.0)
    assert samson_turn_rate(0.5, left_of, PARAMS) < 0 < samson_turn_rate(0.5, right_of, PARAMS)
    assert samson_turn_rate(0.0, left_of, PARAMS) == 0.0


@pytest.mark.parametrize(
    "field, value",
    [("gain_lateral", -1.0), ("lateral_acc", 0.0), ("check_margin", -0.1)],
)
def test_parameters_that_cannot_work_are_refused_naming_the_field(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        TrackerParams(**{field: value}).validate()
