"""SLAM for a robot started with no known pose (``agents.placing``): it maps in its own frame,
whose origin is where it woke, and once placed tracks in the fleet's frame.

A robot runs in SimCore on the built-in home world with its odometry started at (0, 0, 0)
(``own_frame``), as the agent of ``--unknown-start`` asks; truth places the body and checks.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from slam_sim import drive_sim

from agents.placing import UnplacedSlamPose
from agents.slam.geometry import wrap_angle
from fleet.config import resolve_world
from fleet.params import load_fleet_config
from fleet.world import load_world
from sim_server.core import SimCore

START = (1.0, 1.2, math.radians(30.0))


def _error(a: Sequence[float], b: Sequence[float]) -> tuple[float, float]:
    return math.hypot(a[0] - b[0], a[1] - b[1]), abs(float(wrap_angle(a[2] - b[2])))


def test_an_unplaced_robot_maps_in_its_own_frame_and_tracks_in_the_fleets_once_placed():
    cfg = load_fleet_config()
    core = SimCore(load_world(resolve_world("home"), cfg.robot.radius), cfg, seed=3)
    core.add_robot("r", START, own_frame=True)
    lidar = cfg.lidar
    source = UnplacedSlamPose(cfg.slam, lidar.range_min, lidar.range_max)
    assert not source.place(*START), "placed before any scan"
    drive_sim(core, source, [(2.0, 0.0, 0.0)])
    assert not source.localized and source.own_frame and source.reason
    # its own frame: it stands at the origin, and its map holds walls around there
    assert _error(source.pose(), (0.0, 0.0, 0.0))[0] < 0.02
    own_map = source.occupancy()
    assert own_map is not None and (own_map.log_odds > 0).any()
    # it is pushed on a little (an unplaced robot stands, but the frame must hold all the same)
    drive_sim(core, source, [(2.0, 0.2, 0.0)])
    assert 0.3 < source.pose()[0] < 0.5
    # the coordinator's placement: its frame's origin is where it started
    placed = source.place(*START)
    assert placed is not None
    dxy, dth = _error(placed, core.truth()["r"])
    assert dxy < 0.03 and dth < math.radians(1.0), (placed, core.truth()["r"])
    assert source.localized and not source.own_frame and source.reason == ""
    assert source.place(0.0, 0.0, 0.0) is None, "placed twice"
    drive_sim(core, source, [(4.0, 0.2, 0.0), (3.0, 0.0, 0.5), (3.0, 0.2, 0.0)])
    dxy, dth = _error(source.pose(), core.truth()["r"])
    assert dxy < 0.06 and dth < math.radians(2.0), (source.pose(), core.truth()["r"])
    # the map now lies in the fleet's frame: a wall the truth has is where the map has it
    fleet_map = source.occupancy()
    assert fleet_map is not None
    rows, cols = np.nonzero(fleet_map.log_odds > 1.0)
    xy = np.column_stack(
        [
            fleet_map.origin[0] + (cols + 0.5) * fleet_map.resolution,
            fleet_map.origin[1] + (rows + 0.5) * fleet_map.resolution,
        ]
    )
    world = load_world(resolve_world("home"), cfg.robot.radius)
    near = world.clearance(xy) < 0.1
    assert near.mean() > 0.9, near.mean()
