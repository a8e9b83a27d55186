"""The simulator's pure core: physics, sensors, collisions and ground-truth cleaning, stepped.

No bus here: :class:`SimCore` is driven by the server loop (``sim_server/server.py``) and by the
benchmark, and tested directly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fleet.params import FleetConfig
from fleet.protocol import Collision, CoverageSummary, LaserScan, Odometry
from fleet.world import World
from planners.polyline import count_turns, simplify
from sim_server.cleaning import CleaningGrid, cleanable_mask
from sim_server.lidar import SegmentIndex, add_noise, cast_scans, occupancy_to_segments
from sim_server.odometry import OdometryModel

# Driven paths are sampled every this many metres and simplified with this tolerance before
# turns are counted, so wheel jitter does not count as turning.
TRAJECTORY_SAMPLE_M = 0.05
TURN_SIMPLIFY_TOL_M = 0.05
# Segments above which the lidar uses a spatial index instead of a brute-force cull.
SEGMENT_INDEX_MIN = 400
# A contact between the same pair within this long (sim s) of their previous contact belongs to
# the same collision: a robot grinding along a wall re-touches it many times a second.
COLLISION_DEBOUNCE_S = 1.0


@dataclass
class RobotState:
    rid: str
    odom: OdometryModel
    cmd: tuple[float, float] = (0.0, 0.0)
    v: float = 0.0
    w: float = 0.0
    path_length_m: float = 0.0
    last_xy: tuple[float, float] = (0.0, 0.0)
    samples: list[tuple[float, float]] = field(default_factory=list)
    wall_collisions: int = 0
    robot_collisions: int = 0

    def turns(self) -> int:
        return count_turns(simplify(np.array(self.samples), TURN_SIMPLIFY_TOL_M))


@dataclass
class StepOutput:
    scans: list[tuple[str, LaserScan]] = field(default_factory=list)
    odometry: list[tuple[str, Odometry]] = field(default_factory=list)
    collisions: list[Collision] = field(default_factory=list)


def world_segments(world: World) -> np.ndarray:
    """The static edges the lidar sees: polygon edges, or the boundaries of blocked map cells."""
    if world.map_grid is not None:
        g = world.map_grid
        return occupancy_to_segments(g.occupied | g.unknown, g.resolution, g.origin)
    edges = [np.hstack([poly, np.roll(poly, -1, axis=0)]) for poly in world.polygons]
    return np.vstack(edges)


class SimCore:
    """Steps the world by ``1 / physics_hz`` and emits the sensor data that falls due."""

    def __init__(
        self, world: World, cfg: FleetConfig, seed: int = 0, starts_xy: np.ndarray | None = None
    ) -> None:
        self.world = world
        self.cfg = cfg
        self.rng = np.random.default_rng(seed)
        self.dt = 1.0 / cfg.sim.physics_hz
        self.t = 0.0
        self.steps = 0
        self.scan_every = max(1, round(cfg.sim.physics_hz / cfg.lidar.rate_hz))
        self.odom_every = max(1, round(cfg.sim.physics_hz / cfg.odometry.rate_hz))
        from sim_server.physics import Physics

        self.physics = Physics(world, self._on_contact)
        segs = world_segments(world)
        self.segments: np.ndarray | SegmentIndex = (
            SegmentIndex(segs, reach=cfg.lidar.range_max) if len(segs) > SEGMENT_INDEX_MIN else segs
        )
        lidar = cfg.lidar
        self.angle_min = -lidar.fov / 2
        self.angle_increment = lidar.fov / lidar.beams
        self.beam_angles = self.angle_min + self.angle_increment * np.arange(lidar.beams)
        grid = world.grid(cfg.sim.cell_size)
        if starts_xy is None:
            starts_xy = np.array([p[:2] for p in world.start_poses(1, cfg.robot.radius)])
        cleanable = cleanable_mask(grid, starts_xy, cfg.robot.radius, cfg.robot.cleaning_width)
        self.cleaning = CleaningGrid(grid, cleanable, cfg.robot.cleaning_width)
        self.robots: dict[str, RobotState] = {}
        self.departed: dict[str, RobotState] = {}
        self._pending_collisions: list[Collision] = []
        self._last_contact: dict[tuple[str, str], float] = {}
        self._clearance_grid = world.grid(0.025)

    # ---- robots -------------------------------------------------------------------------

    def check_free(self, pose: tuple[float, float, float], ignore: str = "") -> str:
        """Why ``pose`` cannot take a robot ("" when it can)."""
        r = self.cfg.robot.radius
        clear = float(self.world.clearance(np.array([pose[:2]]))[0])
        if clear < r:
            return f"({pose[0]:.2f}, {pose[1]:.2f}) is within {r} m of a wall or furniture"
        for rid in self.robots:
            if rid == ignore:
                continue
            x, y, _ = self.physics.pose(rid)
            if math.hypot(x - pose[0], y - pose[1]) < 2 * r:
                return f"({pose[0]:.2f}, {pose[1]:.2f}) overlaps robot {rid}"
        return ""

    def add_robot(self, rid: str, pose: tuple[float, float, float]) -> tuple[float, float, float]:
        """Place a robot; a robot that is already in the world stays where it is."""
        if rid in self.robots:
            return self.physics.pose(rid)
        why = self.check_free(pose)
        if why:
            raise ValueError(why)
        self.physics.add_robot(rid, pose, self.cfg.robot.radius, self.cfg.robot.mass)
        old = self.departed.pop(rid, None)
        state = RobotState(rid, OdometryModel(self.cfg.odometry, self.rng, pose))
        if old is not None:
            state.path_length_m = old.path_length_m
            state.samples = old.samples
            state.wall_collisions = old.wall_collisions
            state.robot_collisions = old.robot_collisions
        state.last_xy = (pose[0], pose[1])
        state.samples.append(state.last_xy)
        self.robots[rid] = state
        return pose

    def remove_robot(self, rid: str) -> None:
        state = self.robots.pop(rid, None)
        if state is not None:
            self.physics.remove_robot(rid)
            self.cleaning.forget(rid)
            self.departed[rid] = state

    def set_cmd(self, rid: str, v: float, w: float) -> None:
        if rid in self.robots:
            rp = self.cfg.robot
            v = min(max(v, -rp.max_vel_x), rp.max_vel_x)
            w = min(max(w, -rp.max_vel_theta), rp.max_vel_theta)
            self.robots[rid].cmd = (v, w)

    def _on_contact(self, robot: str, other: str, x: float, y: float) -> None:
        pair = (min(robot, other), max(robot, other)) if other else (robot, "")
        last = self._last_contact.get(pair)
        self._last_contact[pair] = self.t
        if last is not None and self.t - last < COLLISION_DEBOUNCE_S:
            return
        kind = "robot" if other else "wall"
        if other:
            self.robots[robot].robot_collisions += 1
            self.robots[other].robot_collisions += 1
        else:
            self.robots[robot].wall_collisions += 1
        self._pending_collisions.append(Collision(self.t, kind, robot, other, x, y))

    # ---- stepping -----------------------------------------------------------------------

    def step(self) -> StepOutput:
        rp = self.cfg.robot
        dv, dw = rp.acc_lim_x * self.dt, rp.acc_lim_theta * self.dt
        for rid, s in self.robots.items():
            s.v += min(max(s.cmd[0] - s.v, -dv), dv)
            s.w += min(max(s.cmd[1] - s.w, -dw), dw)
            self.physics.drive(rid, s.v, s.w)
        self.physics.step(self.dt)
        self.steps += 1
        self.t = self.steps * self.dt
        for rid, s in self.robots.items():
            x, y, _ = self.physics.pose(rid)
            step = math.hypot(x - s.last_xy[0], y - s.last_xy[1])
            s.path_length_m += step
            s.last_xy = (x, y)
            last = s.samples[-1]
            if math.hypot(x - last[0], y - last[1]) >= TRAJECTORY_SAMPLE_M:
                s.samples.append((x, y))
            self.cleaning.update(rid, x, y)
        out = StepOutput(collisions=self._pending_collisions)
        self._pending_collisions = []
        if not self.robots:
            return out
        if self.steps % self.odom_every == 0:
            for rid, s in self.robots.items():
                ox, oy, oth = s.odom.update(self.physics.pose(rid))
                out.odometry.append((rid, Odometry(self.t, ox, oy, oth, s.v, s.w)))
        if self.steps % self.scan_every == 0:
            out.scans = self.scan_all()
        return out

    def truth(self) -> dict[str, tuple[float, float, float]]:
        return {rid: self.physics.pose(rid) for rid in self.robots}

    def scan_all(self) -> list[tuple[str, LaserScan]]:
        """One noisy scan per robot, all cast in one vectorized call."""
        ids = list(self.robots)
        poses = np.array([self.physics.pose(r) for r in ids])
        discs = np.column_stack([poses[:, :2], np.full(len(ids), self.cfg.robot.radius)])
        lidar = self.cfg.lidar
        ranges = cast_scans(
            poses[:, :2],
            poses[:, 2],
            self.beam_angles,
            self.segments,
            discs,
            lidar.range_max,
            self_index=np.arange(len(ids)),
        )
        ranges = add_noise(ranges, lidar.noise_sigma, lidar.range_min, lidar.range_max, self.rng)
        return [
            (
                rid,
                LaserScan(
                    self.t,
                    self.angle_min,
                    self.angle_increment,
                    lidar.range_min,
                    lidar.range_max,
                    ranges[i].astype(np.float32),
                ),
            )
            for i, rid in enumerate(ids)
        ]

    # ---- metrics ------------------------------------------------------------------------

    def all_robots(self) -> dict[str, RobotState]:
        return {**self.departed, **self.robots}

    def summary(self, wall_s: float) -> CoverageSummary:
        robots = self.all_robots()
        ids = sorted(robots)
        return CoverageSummary(
            stamp=self.t,
            wall_s=wall_s,
            coverage=self.cleaning.coverage(),
            repetition=self.cleaning.repetition(),
            cleanable_m2=self.cleaning.cleanable_m2,
            robots=ids,
            path_length_m=np.array([robots[r].path_length_m for r in ids]),
            turns=np.array([robots[r].turns() for r in ids], dtype=np.int32),
            wall_collisions=np.array([robots[r].wall_collisions for r in ids], dtype=np.int32),
            robot_collisions=np.array([robots[r].robot_collisions for r in ids], dtype=np.int32),
        )
