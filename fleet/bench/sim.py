"""``fleet bench sim``: the simulator core alone with scripted robots (no bus), its real-time
factor and lidar rays per second.

Robots drive arcs whose curvature changes slowly, so they sweep the world, hit walls and each
other. The loop is the live simulator's (``SimCore.tick``): physics, lidar, odometry,
cleaning, true poses and the run's summary at the rates a live run computes them; only the bus
is left out."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from fleet.params import FleetConfig
from fleet.world import World
from sim_server.core import SimCore

# the scripted robots' commands change every this many physics steps
COMMAND_EVERY_STEPS = 10


def run_bench(
    world: World,
    cfg: FleetConfig,
    starts: Sequence[tuple[float, float, float]],
    seconds: float,
) -> dict[str, Any]:
    """One robot per start pose driving arcs for ``seconds`` sim seconds; the figures
    (``rtf``, ``rtf_cpu``: sim seconds per wall and per CPU second of this process, which a
    shared machine disturbs much less; ``load_avg``: the 1-minute load when it finished)."""
    robots = len(starts)
    core = SimCore(world, cfg, seed=0)
    for i, pose in enumerate(starts):
        core.add_robot(f"r{i}", pose)
    rng = np.random.default_rng(1)
    phase = rng.uniform(0, 2 * np.pi, robots)
    steps = round(seconds * cfg.sim.physics_hz)
    scans = 0
    t0, cpu0 = time.perf_counter(), time.process_time()
    for k in range(steps):
        if k % COMMAND_EVERY_STEPS == 0:
            t = core.t
            for i in range(robots):
                core.set_cmd(f"r{i}", 0.4, 0.8 * math.sin(0.3 * t + phase[i]))
        scans += len(core.tick(time.perf_counter() - t0).scans)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - cpu0
    return {
        "robots": robots,
        "world": world.name,
        "sim_seconds": round(core.t, 3),
        "wall_s": round(wall, 3),
        "rtf": round(core.t / wall, 2),
        "cpu_s": round(cpu, 3),
        "rtf_cpu": round(core.t / cpu, 2),
        "load_avg": round(os.getloadavg()[0], 2),
        "rays_per_s": round(scans * cfg.lidar.beams / wall),
        "scans": scans,
        "coverage": round(core.cleaning.coverage(), 4),
    }
