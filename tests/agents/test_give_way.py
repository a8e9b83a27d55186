"""Two robots driven at each other, each by the agents' own control step (SLAM, DWA, giving
way by the other's intent), in the simulator, without processes: they must pass without
touching, and without giving up a waypoint. The same drives with give-way switched off end in
contact (crossing) or stuck face to face (head-on), so the scenes do test it.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from bus_stand_in import LoopbackBus

from agents import control
from agents.agent import Agent, pose_source_for
from agents.control import Drive
from agents.follow.state import FollowState
from fleet.params import FleetConfig, load_fleet_config
from fleet.protocol import Intent, Keys, Message, Twist
from fleet.world import load_world
from sim_server.core import SimCore

# An open 6 m square room, and a 1.4 m wide, 7 m long corridor.
ROOM = """name: room
wall_thickness: 0.1
walls: [[0, 0, 6, 0], [6, 0, 6, 6], [6, 6, 0, 6], [0, 6, 0, 0]]
dock: [0.5, 0.5, 0.0]
starts: [[0.5, 0.5, 0.0]]
"""
CORRIDOR = """name: corridor
wall_thickness: 0.1
walls: [[0, 0, 7, 0], [7, 0, 7, 1.4], [7, 1.4, 0, 1.4], [0, 1.4, 0, 0]]
dock: [0.5, 0.7, 0.0]
starts: [[0.5, 0.7, 0.0]]
"""
# Each scene: the world, and per robot its start and its waypoints. Crossing: paths at right
# angles that reach the room's centre at the same time. Head-on: both along the corridor's
# middle line, towards each other.
SCENES = {
    "crossing": (
        ROOM,
        {
            "robot-0": ((1.0, 3.0, 0.0), [(3.0, 3.0), (5.0, 3.0)]),
            "robot-1": ((3.0, 1.0, math.pi / 2), [(3.0, 3.0), (3.0, 5.0)]),
        },
    ),
    "head-on": (
        CORRIDOR,
        {
            "robot-0": ((0.6, 0.7, 0.0), [(3.5, 0.7), (6.4, 0.7)]),
            "robot-1": ((6.4, 0.7, math.pi), [(3.5, 0.7), (0.6, 0.7)]),
        },
    ),
}
SIM_SECONDS = 40.0


def _drive(scene: str, tmp_path: Path, cfg: FleetConfig) -> tuple[int, int, bool]:
    """Run the scene; returns the robot-robot contacts, the waypoints given up (blocked for
    ``agent.give_up_after_s``) and whether both robots finished their paths in time."""
    text, robots = SCENES[scene]
    (tmp_path / "world.yaml").write_text(text)
    world = load_world(tmp_path / "world.yaml")
    keys = Keys("give-way")
    core = SimCore(world, cfg, seed=0, starts_xy=np.array([p[:2] for p, _ in robots.values()]))
    sent: dict[str, list[tuple[str, Message]]] = {}
    agents = {}
    for rid, (start, waypoints) in robots.items():
        core.add_robot(rid, start)
        agent = Agent(LoopbackBus(keys, sent), rid, cfg)  # type: ignore[arg-type]
        agent.pose_source = pose_source_for(cfg, None, start, unknown_start=False)
        path = np.array([start[:2], *waypoints], dtype=float)
        agent.drive = Drive(plan_id=1, follow=FollowState(path))
        agents[rid] = agent
    for agent in agents.values():  # each is in the job for the others, as its token says
        for rid in agents:
            agent.rx.joined(rid)
    contacts = 0

    def done() -> bool:
        return all(a.drive.follow is not None and a.drive.follow.done for a in agents.values())

    while core.t < SIM_SECONDS and not done():
        out = core.step()
        contacts += sum(c.kind == "robot" for c in out.collisions)
        for rid, msg in out.odometry:
            agents[rid]._on_odom("", msg)
        for rid, scan in out.scans:
            agents[rid].step(scan)
        for key, msg in sent.pop("Intent", []):
            assert isinstance(msg, Intent)
            for agent in agents.values():
                agent._on_intent(key, msg)
        for key, msg in sent.pop("Twist", []):
            assert isinstance(msg, Twist)
            core.set_cmd(keys.robot_of(key), msg.v, msg.w)
        sent.clear()
    skipped = sum(a.drive.follow.skipped for a in agents.values() if a.drive.follow is not None)
    return contacts, skipped, done()


@pytest.fixture(scope="module")
def cfg() -> FleetConfig:
    return load_fleet_config()


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_two_robots_driven_at_each_other_pass_without_contact(
    scene: str, tmp_path: Path, cfg: FleetConfig
) -> None:
    assert _drive(scene, tmp_path, cfg) == (0, 0, True)


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_without_giving_way_the_same_drives_collide(
    scene: str, tmp_path: Path, cfg: FleetConfig, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(control, "to_avoid", lambda *_args, **_kw: np.zeros((0, 2)))
    contacts, skipped, _ = _drive(scene, tmp_path, cfg)
    # crossing, they collide; head-on, each stops before the other (it sees it in its scans)
    # and gives up the waypoint the other stands on
    assert contacts > 0 if scene == "crossing" else skipped > 0
