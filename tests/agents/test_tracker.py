"""The path tracker closed round the simulator: lanes held to the centimetre, a box the map
lacks never touched, and a tracker that does not steer caught."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from agents.control import scan_points
from agents.follow.motion import follow_step
from agents.follow.state import FollowParams, Situation
from agents.follow.track import tracked
from fleet.params import FleetConfig, load_fleet_config
from fleet.world import load_world
from planners.tracking import Frenet
from sim_server.core import SimCore

ROOM = """name: room
wall_thickness: 0.1
walls: [[0, 0, 5, 0], [5, 0, 5, 3], [5, 3, 0, 3], [0, 3, 0, 0]]
dock: [0.5, 0.5, 0.0]
starts: [[0.5, 0.5, 0.0]]
"""
BOX = ROOM + "furniture:\n  - {name: box, type: box, center: [2.5, 1.5], size: [0.3, 0.3]}\n"


def _drive(
    tmp_path: Path,
    world: str,
    path: np.ndarray,
    start: tuple[float, float, float],
    cfg: FleetConfig,
    t_max: float,
) -> tuple[list[tuple[float, float, float]], int, bool]:
    """The true poses of one robot driving ``path`` by the follower from ``start``, the contacts,
    and whether it finished."""
    (tmp_path / "w.yaml").write_text(world)
    core = SimCore(load_world(tmp_path / "w.yaml"), cfg, seed=0, starts_xy=np.array([start[:2]]))
    core.add_robot("r", start)
    params = FollowParams.of(cfg)
    follow = tracked(path, 0, params)
    velocity, poses, contacts = (0.0, 0.0), [], 0
    while core.t < t_max:
        out = core.step()
        contacts += len(out.collisions)
        for _, odom in out.odometry:
            velocity = (odom.v, odom.w)
        for _, scan in out.scans:
            pose = core.truth()["r"]
            poses.append(pose)
            obstacles = scan_points(pose, scan.ranges, scan.angle_min, scan.angle_increment)
            follow, result = follow_step(
                follow, Situation(pose, velocity, obstacles, np.zeros((0, 2))), params
            )
            if result is None:
                return poses, contacts, True
            core.set_cmd("r", result.v, result.w)
    return poses, contacts, False


def _across(poses: list, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    errors = [Frenet.of(p, a, b) for p in poses]
    return np.array([e.left for e in errors if 0.0 <= e.along <= e.length])


@pytest.mark.parametrize("left, heading", [(0.10, -0.35), (-0.10, 0.35)])
def test_from_10_cm_and_20_degrees_off_it_merges_onto_the_lane_without_crossing_it(
    tmp_path: Path, left: float, heading: float
) -> None:
    cfg = load_fleet_config()
    a, b = np.array([0.5, 1.5]), np.array([4.5, 1.5])
    start = (0.5, 1.5 + left, heading)
    poses, contacts, done = _drive(tmp_path, ROOM, np.array([a, b]), start, cfg, 30.0)
    across = _across(poses, a, b)
    assert done and contacts == 0
    assert np.max(-np.sign(left) * across) <= 0.01  # never more than 1 cm beyond the line
    assert np.abs(across[-10:]).max() <= 0.005


def test_with_its_gains_near_zero_it_does_not_merge(tmp_path: Path) -> None:
    """The same start with a tracker that hardly steers: the robot stays off its lane."""
    cfg = load_fleet_config()
    cfg = replace(cfg, tracker=replace(cfg.tracker, gain_lateral=1e-6))
    a, b = np.array([0.5, 1.5]), np.array([4.5, 1.5])
    poses, _, _ = _drive(tmp_path, ROOM, np.array([a, b]), (0.5, 1.55, 0.0), cfg, 30.0)
    assert np.abs(_across(poses, a, b)[-10:]).max() > 0.01


def test_a_lane_entered_from_a_u_turn_stays_within_15_mm(tmp_path: Path) -> None:
    cfg = load_fleet_config()
    path = np.array([[0.5, 1.0], [4.5, 1.0], [4.5, 1.25], [0.5, 1.25]])
    poses, contacts, done = _drive(tmp_path, ROOM, path, (0.5, 1.0, 0.0), cfg, 60.0)
    turned = max(k for k, p in enumerate(poses) if p[0] > 4.45 and p[1] > 1.2)
    across = _across(poses[turned:], path[2], path[3])
    assert done and contacts == 0 and len(across) > 50
    assert np.abs(across).max() <= 0.015


def test_a_box_the_plan_does_not_know_on_the_lane_is_never_touched(tmp_path: Path) -> None:
    cfg = load_fleet_config()
    path = np.array([[0.5, 1.45], [4.5, 1.45]])
    poses, contacts, _ = _drive(tmp_path, BOX, path, (0.5, 1.45, 0.0), cfg, 40.0)
    assert contacts == 0
    xs = np.array([p[0] for p in poses])
    assert xs.max() > 1.9  # it drove up to the box, not stood at the start


@pytest.mark.parametrize("into", [0.006, 0.03])
@pytest.mark.parametrize("side", [1.0, -1.0])
def test_a_box_whose_corner_the_lane_grazes_is_never_touched(
    tmp_path: Path, into: float, side: float
) -> None:
    """A box the plan does not know, its near face ``into`` m inside the body's swept strip
    along the lane (a lane planned before a chest was moved beside it): the robot drives on
    past it or round it, and never touches its corner."""
    cfg = load_fleet_config()
    r = cfg.robot.radius
    near = 1.5 + side * (r - into)  # the box's face nearest the lane at y = 1.5
    centre_y = near + side * 0.2
    world = ROOM + (
        f"furniture:\n  - {{name: box, type: box, center: [2.75, {centre_y}], size: [0.5, 0.4]}}\n"
    )
    path = np.array([[0.5, 1.5], [4.5, 1.5]])
    poses, contacts, _ = _drive(tmp_path, world, path, (0.5, 1.5, 0.0), cfg, 40.0)
    assert contacts == 0
    assert max(p[0] for p in poses) > 2.3  # it drove up to the box's corner at x = 2.5
