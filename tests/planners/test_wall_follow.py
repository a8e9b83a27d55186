"""The wall follower (planners.wall_follow) on simulated scans: a unicycle driven by its
commands, scanned by the simulator's lidar (360 beams, 1 cm noise, the agent's median filter),
keeps its set distance along a straight wall and round an outside corner, and turns out of an
inside corner without touching it."""

from __future__ import annotations

import math

import numpy as np
import pytest
from robots import ROBOT

from agents.control import scan_points
from planners.dwa import rollout
from planners.wall_follow import (
    WallFollowParams,
    nearest_wall_point,
    to_robot_frame,
    wall_follow_step,
)
from sim_server.lidar import add_noise, cast_scans, polygon_edges

PARAMS = WallFollowParams()
RADIUS = ROBOT.radius
DT = 0.1
BEAMS = 360
SETTLE_S = 2.0
TOLERANCE = 0.03


def _distance_to(segments: np.ndarray, xy: np.ndarray) -> float:
    a, b = segments[:, :2], segments[:, 2:]
    ab = b - a
    t = np.clip(((xy - a) * ab).sum(axis=1) / (ab * ab).sum(axis=1), 0.0, 1.0)
    return float(np.min(np.hypot(*(xy - (a + t[:, None] * ab)).T)))


def _drive(
    segments: np.ndarray, pose: tuple[float, float, float], side: int, seconds: float, seed: int
) -> np.ndarray:
    """Rows (t, x, y, θ, distance to the nearest wall, whether the follower saw the wall end
    ahead) of the robot under the wall follower."""
    rng = np.random.default_rng(seed)
    increment = 2 * math.pi / BEAMS
    angles = -math.pi + increment * np.arange(BEAMS)
    velocity = (0.0, 0.0)
    rows = []
    for k in range(round(seconds / DT)):
        ranges = cast_scans(
            np.array([pose[:2]]), np.array([pose[2]]), angles, segments, np.zeros((0, 3)), 6.0
        )[0]
        ranges = add_noise(ranges, 0.01, 0.1, 6.0, rng)
        points = to_robot_frame(scan_points(pose, ranges, -math.pi, increment), pose)
        command = wall_follow_step(points, side, velocity, PARAMS, ROBOT, DT)
        assert command is not None, f"lost the wall at {pose}"
        velocity = (command.v, command.w)
        xs, ys, ths = rollout(pose, np.array([command.v]), np.array([command.w]), np.array([DT]))
        pose = (float(xs[0, 0]), float(ys[0, 0]), float(ths[0, 0]))
        rows.append((k * DT, *pose, _distance_to(segments, np.array(pose[:2])), command.ends))
    return np.array(rows)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("side", [-1, 1])
def test_keeps_its_distance_along_a_straight_wall(side: int, seed: int) -> None:
    wall = np.array([[-1.0, 0.0, 8.0, 0.0]])
    start = (0.0, -side * (PARAMS.distance + 0.05), 0.0)  # 5 cm too far out
    rows = _drive(wall, start, side, 10.0, seed)
    settled = rows[rows[:, 0] >= SETTLE_S, 4]
    assert np.abs(settled - PARAMS.distance).max() <= TOLERANCE
    assert rows[-1, 1] > 1.5  # it drove on, it did not stop beside the wall
    assert not rows[:, 5].any()  # the wall never ended


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("side", [-1, 1])
def test_rounds_an_outside_corner_at_its_distance(side: int, seed: int) -> None:
    """Along the top of a 1.5 m box, round its corner and down its side: the distance to the
    box (to its corner while rounding it) stays within ±3 cm of the set distance."""
    box = np.array([[0.0, 0.0], [1.5, 0.0], [1.5, -1.5], [0.0, -1.5]]) * [1.0, -side]
    edges = polygon_edges([box])
    rows = _drive(edges, (0.1, -side * 0.22, 0.0), side, 20.0, seed)
    settled = rows[rows[:, 0] >= SETTLE_S, 4]
    assert np.abs(settled - PARAMS.distance).max() <= TOLERANCE
    assert -side * rows[-1, 2] < -1.0  # turned the corner and followed the box's side down
    assert rows[:, 5].any()  # it saw the wall end, and circled the corner
    assert rows[:, 1].max() < 1.5 + PARAMS.distance + TOLERANCE


@pytest.mark.parametrize("side", [-1, 1])
def test_turns_out_of_an_inside_corner_without_touching_it(side: int) -> None:
    """Along a room's wall into its corner: the robot turns away and follows the next wall,
    never nearer the walls than its radius."""
    room = polygon_edges([np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 3.0], [0.0, 3.0]])])
    y0 = 0.2 if side == -1 else 2.8  # bottom wall on its right, or top wall on its left
    rows = _drive(room, (1.5, y0, 0.0), side, 20.0, 0)
    assert rows[:, 4].min() > RADIUS
    assert abs(rows[-1, 2] - y0) > 1.0  # along the right-hand wall, away from the corner
    assert abs(rows[-1, 1] - (3.0 - PARAMS.distance)) <= TOLERANCE


@pytest.mark.parametrize("rise", [0.05, -0.05])
def test_a_staircase_wall_is_followed_without_contact(rise: float) -> None:
    """A wall a few degrees off a map's axes, as the recorded apartment draws it: a 5 cm step
    every 0.7 m, toward the robot or away from it. The steps toward it are steered away from
    before they are reached (the nearest-point law alone ran 1.9 cm into the first one)."""
    steps = []
    for k in range(8):
        x, y = -1.0 + 0.7 * k, rise * k
        steps += [[x, y, x + 0.7, y], [x + 0.7, y, x + 0.7, y + rise]]
    rows = _drive(np.array(steps), (-0.9, PARAMS.distance, 0.0), -1, 20.0, 0)
    assert rows[:, 4].min() > RADIUS + 0.01
    assert rows[-1, 1] > 1.0


def test_no_wall_near_is_no_command() -> None:
    far = np.array([[2.0, -2.0], [2.1, -2.0]])
    assert wall_follow_step(far, -1, (0.2, 0.0), PARAMS, ROBOT, DT) is None
    with pytest.raises(ValueError, match="side"):
        wall_follow_step(far, 0, (0.2, 0.0), PARAMS, ROBOT, DT)


def test_the_fitted_wall_is_not_pulled_in_by_the_noise() -> None:
    """The nearest of many noisy returns reads short of a wall 0.2 m away (by about a noise
    sigma); the line fitted to them does not."""
    raw, fitted = [], []
    x = np.linspace(-0.3, 0.3, 60)
    for seed in range(100):
        rng = np.random.default_rng(seed)
        points = np.column_stack([x, -0.2 + 0.006 * rng.standard_normal(len(x))])
        raw.append(float(np.hypot(*nearest_wall_point(points, -1, 0.45))) - 0.2)
        fitted.append(float(np.hypot(*nearest_wall_point(points, -1, 0.45, 0.12))) - 0.2)
    assert np.mean(raw) < -0.005
    assert abs(np.mean(fitted)) < 0.001 and np.std(fitted) < 0.002
