"""`fleet bench dashboard`, what the live view costs (:func:`measure`), and the synthetic fleet
it watches (:func:`run`): one process that puts on the bus what a real fleet of N robots does,
at the rates of configs/fleet.yaml times the speed factor, without the work behind it (no
physics, SLAM or planning), so the dashboard's cost can be measured under a known, repeatable
load on a machine that could not run N real agents at that speed.

Robots drive circles around their start poses; the floor plan is the world's grid, served
on the coordinator's key; the cleaned area is served on the simulator's key and grows under
the robots; the coordinator's state and an event come every sim second.
"""

from __future__ import annotations

import io
import math
import os
import subprocess
import sys
import time
from typing import Any

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


# the dashboard is measured after this many wall seconds of drawing
WARMUP_S = 3.0


def measure(
    robots: int,
    speed: float,
    seconds: float,
    width: int,
    height: int,
    world: str,
    redraw_hz: float,
) -> dict[str, Any]:
    """A router and the synthetic fleet (:func:`run`) as two processes, and the dashboard
    drawn here as `fleet dashboard` draws it, at ``redraw_hz``, for a ``width`` × ``height``
    terminal, into memory: ``seconds`` measured after WARMUP_S. Its redraws per second, CPU
    share of one core, frame times and the control-rate messages it drained; StartError when
    the router does not come up."""
    from fleet.supervisor.fleet_processes import StartError
    from fleet.supervisor.launcher import free_port, wait_for_port

    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    cli = [sys.executable, "-m", "fleet.cli"]
    procs = [subprocess.Popen([*cli, "router", "--listen", endpoint], stderr=subprocess.DEVNULL)]
    try:
        if not wait_for_port("127.0.0.1", port, 15.0):
            raise StartError("the Zenoh router did not start")
        code = (
            "import sys; from fleet.bench.dashboard import run; "
            "run(sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), sys.argv[4])"
        )
        procs.append(
            subprocess.Popen([sys.executable, "-c", code, endpoint, str(robots), str(speed), world])
        )
        drawn = _draw(endpoint, seconds, width, height, 1.0 / redraw_hz)
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            p.wait(timeout=10)
    figures = {"robots": robots, "speed": speed, "world": world, "size": f"{width}x{height}"}
    return {**figures, **drawn, "load_avg": round(os.getloadavg()[0], 2)}


def _draw(endpoint: str, seconds: float, width: int, height: int, period: float) -> dict[str, Any]:
    """Draw the fleet on ``endpoint`` every ``period`` wall seconds; the figures."""
    from fleet.dashboard.model import BusFeed, FleetWatcher
    from fleet.dashboard.view import AnsiWriter, screen

    bus = Bus("dashboard", f"bench-{os.getpid()}", [endpoint])
    watcher = FleetWatcher()
    feed = BusFeed(bus, watcher)
    out = io.StringIO()
    writer = AnsiWriter("truecolor")
    t_start = time.monotonic()
    frames: list[float] = []
    received = 0
    cpu0 = wall0 = None
    try:
        while True:
            tick = time.monotonic()
            if cpu0 is None and tick - t_start >= WARMUP_S:
                cpu0, wall0, received, frames = time.process_time(), tick, 0, []
            if wall0 is not None and tick - wall0 >= seconds:
                break
            received += feed.pump()
            lines = screen(watcher.snapshot(), width, height, "robot-0", "bench")
            out.write(writer.frame(lines))
            frames.append(time.monotonic() - tick)
            out.seek(0)
            out.truncate()
            time.sleep(max(0.0, period - (time.monotonic() - tick)))
        cpu = time.process_time() - cpu0
        wall = time.monotonic() - wall0
    finally:
        feed.close()
        bus.close()
    snap = watcher.snapshot()
    frames.sort()
    return {
        "wall_s": round(wall, 2),
        "redraw_hz": round(len(frames) / wall, 2),
        "cpu_percent": round(100 * cpu / wall, 2),
        "frame_ms_p50": round(1000 * frames[len(frames) // 2], 2),
        "frame_ms_max": round(1000 * frames[-1], 2),
        "ring_msgs_per_s": round(received / wall, 1),
        "robots_seen": len(snap.robots),
        "floor_plan": snap.floor is not None,
    }
