"""The simulator's pure core: physics, sensors, collisions and ground-truth cleaning, stepped.

No bus here: :class:`SimCore` is driven by the server loop (``sim_server/server.py``) and by the
benchmark, and tested directly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fleet.config import ConfigError
from fleet.params import FleetConfig
from fleet.protocol import BatteryState, Collision, CoverageSummary, LaserScan, Odometry
from fleet.world import World
from planners.polyline import TurnCounter
from sim_server.battery import Batteries, BatteryLog
from sim_server.cleaning import CleaningGrid, cleanable_mask
from sim_server.lidar import (
    SegmentIndex,
    add_noise,
    cast_scans,
    occupancy_to_segments,
    polygon_edges,
)
from sim_server.odometry import OdometryModel

# Driven paths are sampled every this many metres and simplified with this tolerance before
# turns are counted, so wheel jitter does not count as turning.
TRAJECTORY_SAMPLE_M = 0.05
TURN_SIMPLIFY_TOL_M = 0.05
# ... in finished stretches of this many samples (100 m of driving), so a robot's turn count
# keeps a bounded memory however long the run (planners.polyline.TurnCounter).
TURN_STRETCH_POINTS = 2000
# Segments above which the lidar uses a spatial index instead of a brute-force cull.
SEGMENT_INDEX_MIN = 400
# A contact between the same pair within this long (sim s) of their previous contact belongs to
# the same collision: a robot grinding along a wall re-touches it many times a second.
COLLISION_DEBOUNCE_S = 1.0
# The cleaning grid sweeps each robot's brush along the chord between its poses this often. At
# the robot's top speeds v, ω the arc between two updates leaves its chord by ≤ v·ω/(8·hz²),
# under a millimetre for the robot of configs/fleet.yaml, far below the 5 cm cells. summary()
# sweeps up to the current poses; the grid itself is current at every step the default
# coverage rate (2 Hz) publishes it.
CLEANING_HZ = 10.0
# The true poses go to the dashboard and the report this often.
TRUTH_HZ = 10.0
# Each robot's battery sensor reads this often (with robot.battery on).
BATTERY_HZ = 2.0


@dataclass
class RobotState:
    """A robot's metrics; they outlive its departure and continue when it comes back.

    While the robot is in the world its distance driven accumulates in :class:`SimCore`'s
    arrays; ``path_length_m`` is brought up to date by :meth:`SimCore.all_robots`. Its driven
    path, sampled every ``TRAJECTORY_SAMPLE_M``, goes into ``trajectory``, which keeps the turns
    counted so far, so a summary does not simplify the whole path again, and only the open
    stretch of ``TURN_STRETCH_POINTS`` samples of the path itself.
    """

    rid: str
    path_length_m: float = 0.0
    trajectory: TurnCounter = field(
        default_factory=lambda: TurnCounter(TURN_SIMPLIFY_TOL_M, stretch_points=TURN_STRETCH_POINTS)
    )
    wall_collisions: int = 0
    robot_collisions: int = 0
    battery: BatteryLog = field(default_factory=BatteryLog)

    def turns(self) -> int:
        return self.trajectory.turns()


@dataclass
class StepOutput:
    """What one step produced; ``truth`` and ``summary`` are filled by :meth:`SimCore.tick`
    on the steps they fall due."""

    scans: list[tuple[str, LaserScan]] = field(default_factory=list)
    odometry: list[tuple[str, Odometry]] = field(default_factory=list)
    collisions: list[Collision] = field(default_factory=list)
    batteries: list[tuple[str, BatteryState]] = field(default_factory=list)
    truth: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    summary: CoverageSummary | None = None


def world_segments(world: World) -> np.ndarray:
    """The static edges the lidar sees: counter-clockwise polygon edges (see
    :func:`sim_server.lidar.polygon_edges`), or the boundaries of blocked map cells."""
    if world.map_grid is not None:
        g = world.map_grid
        return occupancy_to_segments(g.occupied | g.unknown, g.resolution, g.origin)
    return polygon_edges(world.polygons)


class SimCore:
    """Steps the world by ``1 / physics_hz`` and emits the sensor data that falls due.

    Per-robot state that changes every step (commands, velocities, poses, odometry, distance
    driven) lives in arrays with one row per robot in ``self.robots`` order, so a step costs a
    few numpy calls whatever the number of robots; only the pymunk bodies are touched one by one.
    """

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
        self.clean_every = max(1, round(cfg.sim.physics_hz / CLEANING_HZ))
        self.truth_every = max(1, round(cfg.sim.physics_hz / TRUTH_HZ))
        self.battery_every = max(1, round(cfg.sim.physics_hz / BATTERY_HZ))
        self.summary_every = max(1, round(cfg.sim.physics_hz / cfg.sim.coverage_hz))
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
        self.cleaning = CleaningGrid(
            grid, cleanable, cfg.robot.cleaning_width, cfg.robot.side_brush
        )
        self.robots: dict[str, RobotState] = {}
        self.departed: dict[str, RobotState] = {}
        self._pending_collisions: list[Collision] = []
        self._last_contact: dict[tuple[str, str], float] = {}
        self._ids: list[str] = []
        self._row: dict[str, int] = {}
        self._poses = np.zeros((0, 3))
        self._cmd = np.zeros((0, 2))
        self._vel = np.zeros((0, 2))
        self._path = np.zeros(0)
        self._sampled_xy = np.zeros((0, 2))
        self._odom = OdometryModel(cfg.odometry, self.rng, np.zeros((0, 3)))
        # None with robot.battery off: nothing drains, as before batteries
        self.batteries = Batteries(cfg.robot, world.docks) if cfg.robot.battery.enabled else None
        if self.batteries is not None and not world.docks:
            raise ConfigError(
                f"{world.source}: robot.battery is on, but the world has no dock to charge at "
                "(give it dock: or docks:)"
            )

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
            x, y, _ = self._poses[self._row[rid]]
            if math.hypot(x - pose[0], y - pose[1]) < 2 * r:
                return f"({pose[0]:.2f}, {pose[1]:.2f}) overlaps robot {rid}"
        return ""

    def add_robot(
        self, rid: str, pose: tuple[float, float, float], own_frame: bool = False
    ) -> tuple[float, float, float]:
        """Place a robot; a robot that is already in the world stays where it is. With
        ``own_frame`` its odometry starts at (0, 0, 0), not at ``pose``."""
        if rid in self.robots:
            return self.physics.pose(rid)
        why = self.check_free(pose)
        if why:
            raise ValueError(why)
        self.physics.add_robot(rid, pose, self.cfg.robot.radius, self.cfg.robot.mass)
        state = self.departed.pop(rid, None) or self._new_robot(rid)
        state.trajectory.append(pose[0], pose[1])
        self.robots[rid] = state
        self._reindex()
        self._poses = self.physics.poses(self._ids)
        placed = self._poses[-1:]
        self._cmd = np.vstack([self._cmd, np.zeros((1, 2))])
        self._vel = np.vstack([self._vel, np.zeros((1, 2))])
        self._path = np.append(self._path, state.path_length_m)
        self._sampled_xy = np.vstack([self._sampled_xy, placed[:, :2]])
        self._odom.add(pose, (0.0, 0.0, 0.0) if own_frame else None)
        if self.batteries is not None:
            self.batteries.add(state.battery)
        self.cleaning.update([rid], placed)
        return pose

    def _new_robot(self, rid: str) -> RobotState:
        """A robot new to the world, its battery at ``robot.battery.start_charge``."""
        start = self.cfg.robot.battery.start_charge
        return RobotState(rid, battery=BatteryLog(charge=start, min_charge=start))

    def remove_robot(self, rid: str) -> None:
        state = self.robots.get(rid)
        if state is None:
            return
        i = self._row[rid]
        self.cleaning.update([rid], self._poses[i : i + 1])
        self.cleaning.forget(rid)
        state.path_length_m = float(self._path[i])
        self.physics.remove_robot(rid)
        del self.robots[rid]
        self._reindex()
        self._poses, self._cmd, self._vel, self._path, self._sampled_xy = (
            np.delete(a, i, axis=0)
            for a in (self._poses, self._cmd, self._vel, self._path, self._sampled_xy)
        )
        self._odom.remove(i)
        if self.batteries is not None:
            self.batteries.remove(i)
        self.departed[rid] = state

    def _reindex(self) -> None:
        self._ids = list(self.robots)
        self._row = {rid: i for i, rid in enumerate(self._ids)}

    def set_cmd(self, rid: str, v: float, w: float) -> None:
        i = self._row.get(rid)
        if i is not None:
            rp = self.cfg.robot
            v = min(max(v, -rp.max_vel_x), rp.max_vel_x)
            w = min(max(w, -rp.max_vel_theta), rp.max_vel_theta)
            self._cmd[i] = v, w

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
        ids = self._ids
        if ids:
            rp = self.cfg.robot
            limit = np.array([rp.acc_lim_x, rp.acc_lim_theta]) * self.dt
            if self.batteries is not None:
                # a robot at 0 % stands where it is, whatever it is told
                self._cmd[self.batteries.empty()] = 0.0
            self._vel += np.clip(self._cmd - self._vel, -limit, limit)
            self.physics.drive(ids, self._vel[:, 0], self._vel[:, 1], self._poses[:, 2])
        self.physics.step(self.dt)
        self.steps += 1
        self.t = self.steps * self.dt
        out = StepOutput(collisions=self._pending_collisions)
        self._pending_collisions = []
        if not ids:
            return out
        prev_xy = self._poses[:, :2]
        self._poses = poses = self.physics.poses(ids)
        xy = poses[:, :2]
        self._path += np.hypot(xy[:, 0] - prev_xy[:, 0], xy[:, 1] - prev_xy[:, 1])
        far = np.hypot(xy[:, 0] - self._sampled_xy[:, 0], xy[:, 1] - self._sampled_xy[:, 1])
        for i in np.nonzero(far >= TRAJECTORY_SAMPLE_M)[0].tolist():
            self.robots[ids[i]].trajectory.append(float(xy[i, 0]), float(xy[i, 1]))
            self._sampled_xy[i] = xy[i]
        if self.batteries is not None:
            self.batteries.step(self.dt, self._vel, poses)
            if self.steps % self.battery_every == 0:
                out.batteries = [
                    (rid, BatteryState(self.t, b.charge, b.docked))
                    for rid, b in zip(ids, self.batteries.logs, strict=True)
                ]
        if self.steps % self.clean_every == 0:
            self.cleaning.update(ids, poses)
        if self.steps % self.odom_every == 0:
            odom = self._odom.update(poses).tolist()
            vel = self._vel.tolist()
            out.odometry = [
                (rid, Odometry(self.t, *o, *v)) for rid, o, v in zip(ids, odom, vel, strict=True)
            ]
        if self.steps % self.scan_every == 0:
            out.scans = self.scan_all()
        return out

    def tick(self, wall_s: float) -> StepOutput:
        """One pass of the live simulator's loop (``SimServer.run``): a step, with the true poses
        at ``TRUTH_HZ`` and the summary at ``sim.coverage_hz`` when they fall due. ``fleet bench
        sim`` runs this loop too, so it pays what a live run pays but the bus."""
        out = self.step()
        if self.steps % self.truth_every == 0:
            out.truth = self.truth()
        if self.steps % self.summary_every == 0:
            out.summary = self.summary(wall_s)
        return out

    def truth(self) -> dict[str, tuple[float, float, float]]:
        poses = self._poses.tolist()
        return {rid: (p[0], p[1], p[2]) for rid, p in zip(self._ids, poses, strict=True)}

    def scan_all(self) -> list[tuple[str, LaserScan]]:
        """One noisy scan per robot, all cast in one vectorized call."""
        ids = self._ids
        poses = self._poses
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
            one_sided=self.world.map_grid is None,
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
        """Every robot that has been in the world, with its metrics up to now."""
        for rid, length in zip(self._ids, self._path.tolist(), strict=True):
            self.robots[rid].path_length_m = length
        return {**self.departed, **self.robots}

    def summary(self, wall_s: float) -> CoverageSummary:
        """Metrics so far; sweeps the cleaning grid up to the current poses first."""
        if self._ids:
            self.cleaning.update(self._ids, self._poses)
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
            **self._battery_figures(robots, ids),
        )

    def _battery_figures(self, robots: dict[str, RobotState], ids: list[str]) -> dict:
        """The summary's battery arrays, one entry per robot of ``ids`` (none with batteries
        off)."""
        if self.batteries is None:
            return {}
        logs = [robots[r].battery for r in ids]
        return {
            "charge": np.array([b.charge for b in logs]),
            "min_charge": np.array([b.min_charge for b in logs]),
            "charges": np.array([b.charges for b in logs], dtype=np.int32),
            "charging_s": np.array([b.charging_s for b in logs]),
            "docked": np.array([b.docked for b in logs], dtype=np.uint8),
        }
