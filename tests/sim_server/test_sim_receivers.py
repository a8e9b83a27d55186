"""What the simulator believes of a cmd_vel: a command answers the newest scan its robot was
sent and asks for no more than the robot can drive; anything else is dropped and counted, and
never moves the lockstep."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
from bus_stand_in import NoBus
from waits import wait_until

from fleet.bus import Bus
from fleet.params import load_fleet_config
from fleet.protocol import Keys, LaserScan, SpawnReply, SpawnRequest, Twist
from fleet.supervisor.launcher import free_port
from fleet.world import load_world
from sim_server.server import SimServer

WORLD = Path(__file__).resolve().parents[2] / "configs" / "worlds" / "small.yaml"
CMD = Keys().robot("robot-0", "cmd_vel")
CFG = load_fleet_config(None)


def _server() -> tuple[SimServer, NoBus]:
    bus = NoBus()
    world = load_world(WORLD, CFG.robot.radius)
    server = SimServer(bus, world, CFG)  # type: ignore[arg-type]
    x, y, th = world.start_poses(1, CFG.robot.radius)[0]
    assert server._on_spawn(SpawnRequest("robot-0", x, y, th)).ok
    for _ in range(20):
        server._tick()
    return server, bus


def test_a_command_stamped_after_the_newest_scan_is_dropped_and_moves_no_lockstep() -> None:
    server, bus = _server()
    link = server.links["robot-0"]
    ack = link.ack
    newest = server.scan_stamps["robot-0"]
    server._on_cmd(CMD, Twist(newest + 0.01, 0.3, 0.0))
    server._on_cmd(CMD, Twist(1e12, 0.3, 0.0))
    assert link.ack == ack and not link.answered
    assert [(s, "later than" in why) for _, s, why in bus.dropped] == [("robot-0", True)] * 2
    server._on_cmd(CMD, Twist(newest, 0.3, 0.0))
    assert link.ack == newest and link.answered and len(bus.dropped) == 2


def test_a_command_beyond_what_the_robot_can_drive_is_dropped_a_little_over_is_clamped() -> None:
    server, bus = _server()
    newest = server.scan_stamps["robot-0"]
    top = CFG.robot.max_vel_x
    server._on_cmd(CMD, Twist(newest, 100.0, 0.0))
    server._on_cmd(CMD, Twist(newest, 0.0, -50.0))
    assert not server.links["robot-0"].answered
    assert [s for _, s, _ in bus.dropped] == ["robot-0"] * 2
    assert all("beyond what the robot can drive" in why for *_, why in bus.dropped)
    # a controller ramping down from a measured speed a little over the top (odometry noise)
    server._on_cmd(CMD, Twist(newest, top + 0.01, 0.0))
    assert server.links["robot-0"].answered and len(bus.dropped) == 2
    i = server.core._row["robot-0"]
    assert tuple(server.core._cmd[i]) == (top, 0.0)


def test_a_command_for_a_robot_not_in_the_world_is_dropped() -> None:
    server, bus = _server()
    server._on_cmd(Keys().robot("robot-7", "cmd_vel"), Twist(0.0, 0.1, 0.0))
    assert bus.dropped and bus.dropped[0][1] == "robot-7"
    assert "robot-7" not in server.links


@pytest.fixture
def sim(router_endpoint: str) -> Iterator[tuple[SimServer, Bus, Bus]]:
    """A simulator at --speed 0 (as fast as its agents answer) on a real router, and an agent's
    bus beside it."""
    fleet = f"t{free_port()}"
    sim_bus = Bus("sim", "sim", connect=[router_endpoint], fleet=fleet)
    agent_bus = Bus("agent", "robot-0", connect=[router_endpoint], fleet=fleet)
    world = load_world(WORLD, CFG.robot.radius)
    server = SimServer(sim_bus, world, CFG, speed=0.0)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    try:
        yield server, sim_bus, agent_bus
    finally:
        server.stop.set()
        thread.join(timeout=5.0)
        agent_bus.close()
        sim_bus.close()


@pytest.mark.timeout(60)
def test_a_twist_stamped_far_ahead_does_not_switch_the_lockstep_off(
    sim: tuple[SimServer, Bus, Bus],
) -> None:
    server, sim_bus, agent = sim
    k = agent.keys
    scans: list[float] = []
    agent.subscribe(k.robot("robot-0", "scan"), LaserScan, lambda _k, m: scans.append(m.stamp))
    x, y, th = load_world(WORLD, CFG.robot.radius).start_poses(1, CFG.robot.radius)[0]
    reply = agent.request(k.sim_spawn(), SpawnRequest("robot-0", x, y, th), SpawnReply, 10.0)
    assert reply.ok, reply.error
    assert wait_until(lambda: scans, timeout=10.0), "no scan came"
    first = scans[0]
    held = first + CFG.sim.max_lag_s + server.core.dt
    # the simulator holds at its first scan until the agent answers it
    assert wait_until(lambda: server.links["robot-0"].scanned)
    cmd = k.robot("robot-0", "cmd_vel")

    def forged() -> bool:
        agent.publish(cmd, Twist(1e12, 0.3, 0.0), control=True)
        return server.core.t > held

    # at --speed 0 an unheld simulator runs many sim seconds per wall second
    assert not wait_until(forged, timeout=3.0, poll=0.1), (
        f"sim time ran on to {server.core.t:.2f} s past the first scan at {first:.2f} s"
    )
    assert sim_bus.implausible["robot/*/cmd_vel"] > 0, "the forged commands were not counted"
    assert server.summary().implausible == sim_bus.implausible["robot/*/cmd_vel"]
    # the real answer to the scan moves the lockstep on by one scan
    agent.publish(cmd, Twist(first, 0.0, 0.0), control=True)
    assert wait_until(lambda: len(scans) > 1, timeout=10.0)
    assert server.core.t < scans[1] + CFG.sim.max_lag_s + 2 * server.core.dt
