"""A synthetic fleet for `fleet bench dashboard`: one process that puts on the bus what a real
fleet of N robots does, at the rates of configs/fleet.yaml times the speed factor, without
the work behind it (no physics, SLAM or planning), so the dashboard's cost can be measured
under a known, repeatable load on a machine that could not run N real agents at that speed.

Robots drive circles around their start poses; the floor plan is the world's grid, served
on the coordinator's key; the cleaned area is served on the simulator's key and grows under
the robots; the coordinator's state and an event come every sim second.
"""

from __future__ import annotations

import math
import time

import numpy as np

from fleet.bus import Bus
from fleet.config import resolve_world
from fleet.floor_map import pack_grid
from fleet.params import load_fleet_config
from fleet.protocol import (
    Clock,
    CoverageImage,
    CoverageSummary,
    FleetEvent,
    FleetState,
    Heartbeat,
    Intent,
    LaserScan,
    Odometry,
    PoseEstimate,
    Request,
    RobotStatus,
    TruthPose,
    Twist,
)
from fleet.world import load_world
from sim_server.core import TRUTH_HZ

CIRCLE_M = 0.6
# robots circle at this share of the robot's top speed
SPEED_SHARE = 0.6
INTENT_POINTS = 20
TASKS = 40


def run(endpoint: str, robots: int, speed: float, world: str, seconds: float = 3600.0) -> None:
    """Publish a fleet of ``robots`` at ``speed``× until killed or ``seconds`` have passed."""
    cfg = load_fleet_config(None)
    w = load_world(resolve_world(world), cfg.robot.radius)
    grid = w.grid(cfg.sim.cell_size)
    starts = w.start_poses(robots, cfg.robot.radius)
    ids = [f"robot-{i}" for i in range(robots)]
    sim = Bus("sim", "synthetic", [endpoint])
    coord = Bus("coordinator", "synthetic", [endpoint])
    agents = [Bus("agent", rid, [endpoint]) for rid in ids]
    visits = np.zeros(grid.shape, dtype=np.uint16)
    cleanable = grid.free.astype(np.uint8)
    floor = pack_grid(grid)
    coord.serve(coord.keys.floor_map(), Request, lambda _r: floor)

    def image(_req: Request) -> CoverageImage:
        return CoverageImage(
            t, grid.resolution, *grid.origin, *grid.shape, visits.reshape(-1), cleanable.reshape(-1)
        )

    sim.serve(sim.keys.coverage_image(), Request, image)
    k = sim.keys
    dt = 1.0 / cfg.sim.physics_hz
    every = {
        "odom": round(cfg.sim.physics_hz / cfg.odometry.rate_hz),
        "scan": round(cfg.sim.physics_hz / cfg.lidar.rate_hz),
        "truth": round(cfg.sim.physics_hz / TRUTH_HZ),
        "control": round(cfg.sim.physics_hz / cfg.agent.control_hz),
        "status": round(cfg.sim.physics_hz / cfg.agent.status_hz),
        "clock": round(cfg.sim.physics_hz / cfg.sim.clock_hz),
        "coverage": round(cfg.sim.physics_hz / cfg.sim.coverage_hz),
        "state": round(cfg.sim.physics_hz),
    }
    ranges = np.full(cfg.lidar.beams, 3.0, dtype=np.float32)
    v = cfg.robot.max_vel_x * SPEED_SHARE
    omega = v / CIRCLE_M
    beat_every = 1.0 / cfg.agent.heartbeat_hz
    wall0 = last_beat = time.monotonic()
    t = 0.0
    step = 0
    try:
        while time.monotonic() - wall0 < seconds:
            step += 1
            t = step * dt
            for i, rid in enumerate(ids):
                a = omega * t + i
                cx, cy, _ = starts[i]
                x, y, th = cx + CIRCLE_M * math.cos(a), cy + CIRCLE_M * math.sin(a), a + math.pi / 2
                if step % every["odom"] == 0:
                    sim.publish(k.robot(rid, "odom"), Odometry(t, x, y, th, v, omega))
                if step % every["scan"] == 0:
                    scan = LaserScan(t, -math.pi, 2 * math.pi / len(ranges), 0.1, 6.0, ranges)
                    sim.publish(k.robot(rid, "scan"), scan, control=True)
                if step % every["truth"] == 0:
                    sim.publish(k.robot(rid, "truth"), TruthPose(t, x, y, th))
                    r, c = grid.world_to_cell(np.array([x, y]))
                    if 0 <= r < grid.shape[0] and 0 <= c < grid.shape[1]:
                        visits[max(r - 3, 0) : r + 3, max(c - 3, 0) : c + 3] += 1
                if step % every["control"] == 0:
                    bus = agents[i]
                    bus.publish(k.robot(rid, "cmd_vel"), Twist(t, v, omega), control=True)
                    bus.publish(k.robot(rid, "pose"), PoseEstimate(t, x, y, th))
                    ahead = a + np.linspace(0, 1.2, INTENT_POINTS)
                    pts = np.stack(
                        [
                            t + np.linspace(0, 2, INTENT_POINTS),
                            cx + CIRCLE_M * np.cos(ahead),
                            cy + CIRCLE_M * np.sin(ahead),
                        ],
                        axis=1,
                    )
                    bus.publish(k.robot(rid, "intent"), Intent(t, pts))
                if step % every["status"] == 0:
                    status = RobotStatus(t, "driving", f"t{i:02d}", (t / 600) % 1, 3, 10, v * t)
                    agents[i].publish(k.robot(rid, "status"), status, control=True)
            if step % every["clock"] == 0:
                sim.publish(k.clock(), Clock(t, speed))
            if step % every["coverage"] == 0:
                sim.publish(k.coverage(), _summary(t, time.monotonic() - wall0, ids, visits))
            if step % every["state"] == 0:
                done = min(TASKS - 1, int(t / 10))
                state = FleetState(t, "cleaning", ids, [], [], 0, TASKS - done, done)
                coord.publish(k.coord_state(), state, control=True)
                event = FleetEvent(t, time.time(), "reassigned", ids[step % robots], "t01", "")
                coord.publish(k.events(), event, control=True)
            now = time.monotonic()
            if now - last_beat >= beat_every:
                last_beat = now
                for i, rid in enumerate(ids):
                    agents[i].publish(k.robot(rid, "heartbeat"), Heartbeat(t, step, True))
            ahead_s = t / speed - (time.monotonic() - wall0)
            if ahead_s > 0:
                time.sleep(ahead_s)
    finally:
        for bus in (sim, coord, *agents):
            bus.close()


def _summary(t: float, wall: float, ids: list[str], visits: np.ndarray) -> CoverageSummary:
    n = len(ids)
    zeros = np.zeros(n, dtype=np.int32)
    return CoverageSummary(
        t, wall, float((visits > 0).mean()), 0.1, 60.0, ids, np.zeros(n), zeros, zeros, zeros
    )
