"""A robot that the order of passage holds before a waypoint comes to rest on the one before it,
inside its own cell: driven by the agent's own control step in the simulator, along a straight
transit whose points are the transit graph's cells (0.375 m apart), at full speed."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from bus_stand_in import LoopbackBus

from agents.agent import Agent, pose_source_for
from agents.control import Drive
from agents.follow.state import FollowState
from agents.passage import Waits
from fleet.params import load_fleet_config
from fleet.protocol import Keys, Twist
from fleet.world import load_world
from sim_server.core import SimCore

HALL = """name: hall
wall_thickness: 0.1
walls: [[0, 0, 8, 0], [8, 0, 8, 2], [8, 2, 0, 2], [0, 2, 0, 0]]
dock: [0.5, 1.0, 0.0]
starts: [[0.5, 1.0, 0.0]]
"""
CELL = 0.375


@pytest.mark.parametrize("held_at", [4, 7])
def test_a_robot_held_before_a_cell_rests_on_the_point_before_it(
    tmp_path: Path, held_at: int
) -> None:
    """Its plan lets it head for waypoint ``held_at`` only once robot-0, never heard, has
    passed robot-0's waypoint 2. Told to stop only on reaching the waypoint before, it came to
    rest its braking distance past it (0.25 m from full speed), its body in the cell robot-0
    was to pass first."""
    cfg = load_fleet_config()
    (tmp_path / "hall.yaml").write_text(HALL)
    start = (0.5, 1.0, 0.0)
    core = SimCore(load_world(tmp_path / "hall.yaml"), cfg, seed=0, starts_xy=np.array([start[:2]]))
    core.add_robot("robot-1", start)
    keys, sent = Keys("hold-stop"), {}
    agent = Agent(LoopbackBus(keys, sent), "robot-1", cfg)  # type: ignore[arg-type]
    agent.pose_source = pose_source_for(cfg, None, start, unknown_start=False)
    path = np.array([(0.5 + 0.1 + CELL * k, 1.0) for k in range(12)])
    path[0] = start[:2]
    waits = Waits(np.array([held_at]), ("robot-0",), np.array([7]), np.array([2]))
    agent.drive = Drive(plan_id=3, sweep_from=len(path) - 1, waits=waits, follow=FollowState(path))
    fastest = 0.0
    while core.t < 12.0:
        out = core.step()
        for _, msg in out.odometry:
            agent._on_odom("", msg)
        for _, scan in out.scans:
            agent.step(scan)
        for key, msg in sent.pop("Twist", []):
            assert isinstance(msg, Twist)
            core.set_cmd(keys.robot_of(key), msg.v, msg.w)
            fastest = max(fastest, msg.v)
        sent.clear()
    x = core.truth()["robot-1"][0]
    assert fastest > 0.9 * cfg.robot.max_vel_x, "the robot never came up to full speed"
    assert agent.drive.follow is not None and agent.drive.follow.index == held_at
    assert abs(x - path[held_at - 1, 0]) < 0.06, (x, path[held_at - 1, 0])
