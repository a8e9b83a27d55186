"""The simulator's links to agents, without a bus: who holds a robot's body, and what makes a
let-go agent live again."""

from __future__ import annotations

from pathlib import Path

from bus_stand_in import NoBus

from fleet.params import load_fleet_config
from fleet.protocol import Keys, SpawnRequest, Twist
from fleet.world import load_world
from sim_server.server import SimServer

WORLD = Path(__file__).resolve().parents[2] / "configs" / "worlds" / "small.yaml"
CMD = Keys().robot("robot-0", "cmd_vel")


def _server_with_robot() -> SimServer:
    cfg = load_fleet_config(None)
    world = load_world(WORLD, cfg.robot.radius)
    server = SimServer(NoBus(), world, cfg)  # type: ignore[arg-type]
    x, y, th = world.start_poses(1, cfg.robot.radius)[0]
    assert server._on_spawn(SpawnRequest("robot-0", x, y, th)).ok
    for _ in range(20):
        server._tick()
    return server


def test_a_command_sent_before_the_agent_left_does_not_refuse_its_respawn() -> None:
    server = _server_with_robot()
    last_scan = server.scan_stamps["robot-0"]
    server._on_cmd(CMD, Twist(last_scan, 0.2, 0.0))
    server._on_agent_left("robot-0")
    # the dying agent's last command, overtaken on the way by the news that it left
    server._on_cmd(CMD, Twist(last_scan, 0.2, 0.0))
    assert not server.links["robot-0"].alive
    reply = server._on_spawn(SpawnRequest("robot-0", 0.0, 0.0, 0.0, rejoin=True))
    assert reply.ok, reply.error


def test_a_hung_agent_let_go_is_live_again_on_its_first_new_command() -> None:
    server = _server_with_robot()
    server._release("robot-0", "was lost to the coordinator")
    for _ in range(10):
        server._tick()
    server._on_cmd(CMD, Twist(server.scan_stamps["robot-0"], 0.2, 0.0))
    assert server.links["robot-0"].alive
    reply = server._on_spawn(SpawnRequest("robot-0", 0.0, 0.0, 0.0, rejoin=True))
    assert not reply.ok and "still live" in reply.error
