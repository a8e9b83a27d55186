"""The robot process: sensors in, DWA path following, cmd_vel, pose, intent and status out.

It knows only what a real robot knows: its scans, its odometry, the sim clock and what the
coordinator sends. It takes part in the market (:mod:`agents.market`): it bids on called tasks
from its own pose and commitments, acknowledges the queue it is awarded, drives only plans for
tasks it holds, and reports the pieces of its task it has swept. A thread of its own sends a
heartbeat on wall time, so a hung agent falls silent. With a state directory it saves its SLAM
map and pose every ``agent.state_save_s`` and its pose alone every ``agent.pose_save_s``;
started with ``respawn`` it takes over its robot's body where it stands, finds itself in the
saved map (first within ``respawn_window`` of the saved pose), and bids only once it has.

Each scan triggers one control step; the cmd_vel it publishes carries that
scan's stamp, which is how the simulator knows the agent has kept up. When its odometry is
older than ``stale_after_s`` (sim time) it commands a stop. Paths are followed from the pose
predicted for when the command will take effect (:func:`agents.follower.predict`), by the
latency it measures against the sim clock. It reads the other robots' intents:
while it works it keeps out of the way of those ranked above it, and without work it steps
aside from anyone's (see :mod:`agents.peers`). A transit planned in space and time comes with
its order of passage: the robot holds at a cell's point until the peers it follows through the
next cell have left it, as their intents tell (:mod:`agents.passage`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import math
import queue
import threading
import time
from pathlib import Path

import numpy as np

from agents.follower import (
    FollowState,
    control_step,
    keep_clear,
    predict,
    scan_points,
)
from agents.market import MarketClient, swept_pieces
from agents.passage import Holding, Waits, hold
from agents.peers import cut_out, own_intent, progress, to_avoid
from agents.pose_source import OdometryPose, PoseSource, RelocalizingSlamPose, SlamPose
from agents.slam.persistence import load_state, save_pose, save_state
from agents.slam.slam_map import MapUpdate, PatchTracker, SlamMap
from agents.time_use import step_kind
from fleet.bus import Bus
from fleet.floor_map import unpack_grid
from fleet.params import FleetConfig
from fleet.plan_chain import chain_of, chain_starts, current_task
from fleet.protocol import (
    TIME_KINDS,
    Award,
    AwardAck,
    Clock,
    Heartbeat,
    Intent,
    LaserScan,
    MapPatches,
    Odometry,
    Plan,
    PoseEstimate,
    Request,
    RobotStatus,
    SpawnReply,
    SpawnRequest,
    TaskCall,
    Twist,
)

log = logging.getLogger("agent")

# The latency of a command (sim time from its scan to the clock when it is sent) is smoothed
# with this gain. At --speed 0 the simulator waits for each answer, so it is 0; in real time
# it is the time a control step takes.
LATENCY_GAIN = 0.2
ODOM_WAIT_S = 0.02
MAX_LATENCY_S = 0.5
# task calls of one auction round arrive together: bid on them in one go
BID_GATHER_S = 0.003
# a respawned robot's SLAM estimate of where it stood is itself this far off at most
RESPAWN_MARGIN_XY = 0.05
RESPAWN_MARGIN_THETA = 0.1


class Agent:
    def __init__(self, bus: Bus, rid: str, cfg: FleetConfig, state_dir: Path | None = None) -> None:
        self.bus = bus
        self.state_dir = state_dir
        self.rid = rid
        self.cfg = cfg
        self.keys = bus.keys
        self.scans: queue.Queue[LaserScan] = queue.Queue(maxsize=1)
        self.lock = threading.Lock()
        self.stop = threading.Event()
        self.pose_source: PoseSource | None = None
        self.odom_stamp = -1.0
        self.velocity = (0.0, 0.0)
        self.command = (0.0, 0.0)
        self.latency_s = 0.0
        self.follow: FollowState | None = None
        self.idle = FollowState(np.zeros((0, 2)))
        # the latest intent of each other robot
        self.peers: dict[str, Intent] = {}
        self.waits = Waits.none()
        self.holding = Holding()
        self.plan_id = -1
        self.task = ""
        self.state = "waiting"
        self.distance_m = 0.0
        self.time_s = np.zeros(len(TIME_KINDS))
        self.clock = 0.0
        self._last_xy: tuple[float, float] | None = None
        self._last_status = -1e9
        self._last_map = -1e9
        self._map_seq = 0
        self._map_snapshot: SlamMap | None = None
        self._patches = PatchTracker(cfg.slam.map_tile, cfg.slam.patch_tolerance)
        self.sweep_from = 0
        self.chain: list[str] = []
        self.chain_starts = np.zeros(0, dtype=np.int32)
        self.chain_time_s = 0.0
        self.market = MarketClient(
            rid,
            cfg.agent.transit_speed,
            cfg.robot.radius,
            cfg.slam.occupied_threshold,
            cfg.slam.free_threshold,
        )
        self._calls: list[TaskCall] = []
        self._calls_ready = threading.Condition()
        self._last_save = -1e9
        self._last_pose_save = -1e9
        self._unlocalized_logged = False
        self._was_localized = True

    def spawn(
        self, start: tuple[float, float, float], respawn: bool = False, timeout: float = 30.0
    ) -> None:
        """Ask the simulator to place the robot (with ``respawn``: to hand over the body the
        robot left in the world, and load the saved map and pose from the state directory);
        retry until it answers or ``timeout`` passes.

        The subscriptions come first: the simulator sends the first scan right after placing
        the robot and then holds its clock until that scan is answered."""
        saved = None
        if respawn:
            if self.state_dir is None:
                raise ValueError("a respawn needs the state directory the robot saved to")
            saved = load_state(self.state_dir)
            start = saved.pose
        k = self.keys
        self.bus.subscribe(k.robot(self.rid, "odom"), Odometry, self._on_odom)
        self.bus.subscribe(k.robot(self.rid, "scan"), LaserScan, self._on_scan)
        self.bus.subscribe(k.clock(), Clock, self._on_clock)
        self.bus.subscribe(k.plan(self.rid), Plan, self._on_plan)
        self.bus.subscribe(k.all_robots("intent"), Intent, self._on_intent)
        self.bus.subscribe(k.task("*"), TaskCall, self._on_call)
        self.bus.subscribe(k.award(self.rid), Award, self._on_award)
        self.bus.serve(k.robot(self.rid, "map"), Request, self._on_map_request)
        deadline = time.monotonic() + timeout
        req = SpawnRequest(self.rid, *start, rejoin=respawn)
        while True:
            try:
                reply = self.bus.request(self.keys.sim_spawn(), req, SpawnReply, timeout=2.0)
                break
            except (TimeoutError, RuntimeError) as e:
                if time.monotonic() > deadline:
                    raise TimeoutError(f"no simulator answered the spawn request: {e}") from None
                time.sleep(0.2)
        if not reply.ok:
            raise ValueError(f"spawn refused: {reply.error}")
        with self.lock:
            self._was_localized = saved is None
            if saved is not None:
                lidar = self.cfg.lidar
                self.pose_source = RelocalizingSlamPose(
                    self.cfg.slam,
                    saved,
                    lidar.range_min,
                    lidar.range_max,
                    near=respawn_window(self.cfg),
                )
            else:
                self.pose_source = self._make_pose_source((reply.x, reply.y, reply.theta))
        if saved is not None:
            log.info(
                "%s took over its body; finding itself in its saved map near (%.2f, %.2f, %.2f)",
                self.rid,
                *saved.pose,
            )
        else:
            log.info(
                "%s spawned at (%.2f, %.2f, %.2f), pose from %s",
                self.rid,
                reply.x,
                reply.y,
                reply.theta,
                self.pose_source.name,
            )

    def _make_pose_source(self, start: tuple[float, float, float]) -> PoseSource:
        if self.cfg.agent.pose_source == "odometry":
            return OdometryPose(start)
        lidar = self.cfg.lidar
        return SlamPose(self.cfg.slam, start, lidar.range_min, lidar.range_max)

    def fetch_plan(self) -> None:
        """Late joiners ask the coordinator for their current plan instead of waiting for one."""
        try:
            plan = self.bus.request(self.keys.plan(self.rid), Request(self.rid), Plan, timeout=1.0)
        except (TimeoutError, RuntimeError):
            return
        self._on_plan("", plan)

    # ---- bus callbacks ------------------------------------------------------------------

    def _on_odom(self, _key: str, msg: Odometry) -> None:
        with self.lock:
            if self.pose_source is None:
                return
            self.pose_source.on_odometry(msg)
            self.odom_stamp = msg.stamp
            self.velocity = (msg.v, msg.w)

    def _on_scan(self, _key: str, msg: LaserScan) -> None:
        with contextlib.suppress(queue.Empty):
            self.scans.get_nowait()
        self.scans.put_nowait(msg)

    def _on_intent(self, key: str, msg: Intent) -> None:
        rid = self.keys.robot_of(key)
        if rid != self.rid:
            with self.lock:
                self.peers[rid] = msg

    def _on_clock(self, _key: str, msg: Clock) -> None:
        self.clock = max(self.clock, msg.stamp)

    def _on_plan(self, _key: str, msg: Plan) -> None:
        with self.lock:
            if msg.plan_id == self.plan_id:
                self._cut_plan(msg)
                return
            if not self.market.holds(msg.task):
                return
            self.plan_id = msg.plan_id
            self.task = msg.task
            self.sweep_from = msg.sweep_from
            self.chain = chain_of(msg)
            self.chain_starts = chain_starts(msg)
            self.chain_time_s = sum(w.time_s for w in self.market.queue if w.id in self.chain)
            self.follow = FollowState(msg.waypoints) if len(msg.waypoints) else None
            self.waits = Waits.of(msg)
            self.state = "driving" if self.follow is not None else "done"
        log.info(
            "%s: plan %d (%s) with %d waypoints",
            self.rid,
            msg.plan_id,
            msg.task,
            len(msg.waypoints),
        )

    def _cut_plan(self, msg: Plan) -> None:
        """The coordinator took back the end of the plan being driven (tasks it gave to others):
        stop at its new end, driving on as before until there."""
        follow = self.follow
        if follow is None or len(msg.waypoints) >= len(follow.waypoints):
            return
        self.follow = dataclasses.replace(follow, waypoints=msg.waypoints)
        self.chain = chain_of(msg)
        self.chain_starts = chain_starts(msg)
        self.chain_time_s = sum(w.time_s for w in self.market.queue if w.id in self.chain)
        log.info("%s: plan %d now ends after %s", self.rid, msg.plan_id, self.chain[-1])

    def _on_award(self, _key: str, msg: Award) -> None:
        with self.lock:
            taken = self.market.on_award(msg)
            driving = self.follow is not None and not self.follow.done
            dropped = taken and driving and not any(self.market.holds(t) for t in self.chain)
            if dropped:
                self.follow = None
                self.task = ""
            seq = self.market.seq
        self.bus.publish(self.keys.ack(self.rid), AwardAck(self.clock, seq, self.rid), True)
        if taken:
            log.info("%s: award %d, queue %s", self.rid, seq, " ".join(msg.tasks) or "empty")
        if dropped:
            log.warning("%s: its task went to another robot; stopping it", self.rid)

    def _on_call(self, _key: str, msg: TaskCall) -> None:
        with self._calls_ready:
            self._calls.append(msg)
            self._calls_ready.notify()

    @property
    def ready(self) -> bool:
        """Whether the robot may take work: it knows where it is."""
        src = self.pose_source
        return src is not None and src.localized

    def bid_loop(self) -> None:
        """Answer the task calls of each auction round, all of a round's calls in one go."""
        while not self.stop.is_set():
            with self._calls_ready:
                if not self._calls:
                    self._calls_ready.wait(0.1)
                    continue
            time.sleep(BID_GATHER_S)
            with self._calls_ready:
                calls, self._calls = self._calls, []
            if not self.ready:
                continue
            if not self.market.has_floor:
                self._fetch_floor()
            latest = max(c.round for c in calls)
            calls = [c for c in calls if c.round == latest]
            with self.lock:
                assert self.pose_source is not None
                self.market.use_map(self._map_snapshot)
                commitment = self.market.commitment(
                    self.pose_source.pose(), self.follow, self.chain, self.chain_time_s
                )
                bids = self.market.bids(calls, commitment)
            for b in bids:
                self.bus.publish(self.keys.bid(b.task, self.rid), b, control=True)

    def _fetch_floor(self) -> None:
        try:
            msg = self.bus.request(self.keys.floor_map(), Request(self.rid), MapPatches, 1.0)
        except (TimeoutError, RuntimeError, ValueError) as e:
            log.warning(
                "%s: no floor plan from the coordinator (%s); pricing on its own map", self.rid, e
            )
            return
        floor = unpack_grid(msg)
        with self.lock:
            self.market.use_floor(floor)

    def heartbeat_loop(self) -> None:
        """A heartbeat every 1 / ``agent.heartbeat_hz`` wall seconds, whatever sim time does."""
        period = 1.0 / self.cfg.agent.heartbeat_hz
        seq = 0
        while not self.stop.wait(period):
            seq += 1
            self.bus.publish(
                self.keys.robot(self.rid, "heartbeat"), Heartbeat(self.clock, seq, self.ready)
            )

    def _on_map_request(self, _req: Request) -> MapPatches:
        """The whole current map, for whoever joins late or noticed a gap in ``seq``."""
        snapshot = self._map_snapshot
        if snapshot is None:
            raise LookupError(f"{self.rid} has no map yet")
        update = PatchTracker(self.cfg.slam.map_tile, 0).update(snapshot)
        return _map_message(self.clock, self._map_seq, self.cfg.slam.map_tile, update)

    # ---- control ------------------------------------------------------------------------

    def step(self, scan: LaserScan) -> Twist:
        """One control step on a fresh scan."""
        a = self.cfg.agent
        # The odometry of the scan's moment is sent first but on another stream; give it a
        # moment to arrive, so SLAM pairs the scan with it (see SlamPose).
        deadline = time.monotonic() + ODOM_WAIT_S
        while self.odom_stamp < scan.stamp - 1e-9 and time.monotonic() < deadline:
            time.sleep(0.001)
        with self.lock:
            src = self.pose_source
            assert src is not None
            src.on_scan(cut_out(scan, src.pose(), self.peers, a.stale_after_s, self.cfg.robot))
            pose = src.pose()
            velocity = self.velocity
            stale = scan.stamp - self.odom_stamp > a.stale_after_s
            follow = self.follow
            plan_id, sweep_from, waits = self.plan_id, self.sweep_from, self.waits
            heading_for = None if follow is None else follow.index
            task = current_task(self.chain, self.chain_starts, heading_for) or self.task
            planned = plan_id >= 0
            localized = src.localized
            failed = src.failed
        if localized and not self._was_localized:
            log.info("%s found itself at (%.2f, %.2f, %.2f) in its saved map", self.rid, *pose)
        self._was_localized = localized
        if self._last_xy is not None:
            self.distance_m += float(
                np.hypot(pose[0] - self._last_xy[0], pose[1] - self._last_xy[1])
            )
        self._last_xy = pose[:2]
        v = w = 0.0
        obstacles = scan_points(pose, scan.ranges, scan.angle_min, scan.angle_increment)
        dt = 1.0 / self.cfg.lidar.rate_hz
        kind = "other"
        if stale:
            state = "stale"
        elif not localized:
            state = "unlocalized" if failed else "localizing"
            if failed and not self._unlocalized_logged:
                self._unlocalized_logged = True
                log.error(
                    "%s cannot find itself in its saved map (%s); it stays out of the market",
                    self.rid,
                    src.reason,
                )
        elif follow is None or follow.done:
            state = "done" if planned else "waiting"
            kind = "idle"
            self.idle, result = keep_clear(
                self.idle,
                pose,
                velocity,
                obstacles,
                self._peer_centres(scan.stamp, everyone=True),
                self.cfg.dwa,
                self.cfg.robot,
                dt,
                a,
            )
            v, w = result.v, result.w
        elif (held := self._hold(follow, pose, plan_id, waits, scan.stamp)) is not None:
            follow, state, kind = held, "holding", "hold"
        else:
            before = follow
            # on a transit planned in space and time the plan orders it against the peers it
            # waits for (and that wait for it): it gives way by rank to the others only
            ordered = frozenset(waits.peer) if follow.index <= sweep_from else frozenset()
            follow, result = control_step(
                follow,
                predict(pose, self.command, self.latency_s),
                velocity,
                obstacles,
                self.cfg.dwa,
                self.cfg.robot,
                dt,
                a,
                self._peer_centres(scan.stamp, everyone=False, skip=ordered),
                self.cfg.wall_follow if a.edge_pass else None,
            )
            with self.lock:
                if self.follow is not None and self.follow.waypoints is follow.waypoints:
                    if follow.skipped > self.follow.skipped:
                        skipped_at = self.follow.waypoints[self.follow.index]
                        log.warning(
                            "%s gave up on waypoint %d at (%.2f, %.2f): no progress for %.1f s, "
                            "%.3f m short at (%.3f, %.3f, %.2f)",
                            self.rid,
                            self.follow.index,
                            skipped_at[0],
                            skipped_at[1],
                            a.give_up_after_s,
                            float(np.hypot(pose[0] - skipped_at[0], pose[1] - skipped_at[1])),
                            *pose,
                        )
                    self.follow = follow
            kind = step_kind(before, follow, sweep_from)
            if result is None:
                state = "done"
            else:
                v, w = result.v, result.w
                state = "driving" if result.admissible else "blocked"
        self.time_s[TIME_KINDS.index(kind)] += dt
        self.state = state
        self.command = (v, w)
        lag = min(max(self.clock - scan.stamp, 0.0), MAX_LATENCY_S)
        self.latency_s += LATENCY_GAIN * (lag - self.latency_s)
        self._publish(scan.stamp, pose, v, w, follow, plan_id, task, sweep_from)
        return Twist(scan.stamp, v, w)

    def _hold(
        self,
        follow: FollowState,
        pose: tuple[float, float, float],
        plan_id: int,
        waits: Waits,
        stamp: float,
    ) -> FollowState | None:
        """The follower advanced to where the robot stands if it must hold there for a peer
        (its plan's order of passage, :func:`agents.passage.hold`); None if it may drive on."""
        with self.lock:
            peers = progress(self.peers)
        self.holding, ahead, notes = hold(
            self.holding, follow, np.array(pose[:2]), plan_id, waits, peers, stamp, self.cfg.agent
        )
        for level, text in notes:
            log.log(level, "%s %s", self.rid, text)
        if ahead is not None:
            with self.lock:
                if self.follow is not None and self.follow.waypoints is follow.waypoints:
                    self.follow = ahead
        return ahead

    def _peer_centres(
        self, now: float, everyone: bool, skip: frozenset[str] = frozenset()
    ) -> np.ndarray:
        """The discs the robots this one gives way to will cover (:func:`agents.peers.to_avoid`)."""
        with self.lock:
            intents = dict(self.peers)
        return to_avoid(self.rid, intents, now, self.cfg.agent.stale_after_s, everyone, skip)

    def _publish(
        self,
        stamp: float,
        pose: tuple[float, float, float],
        v: float,
        w: float,
        follow: FollowState | None,
        plan_id: int,
        task: str,
        sweep_from: int,
    ) -> None:
        """Command, pose, intent and (at ``agent.status_hz``) status; ``follow``, ``plan_id``,
        ``task`` and ``sweep_from`` as the control step saw them, so a plan arriving meanwhile
        is never reported with the state of the one before."""
        k, a = self.keys, self.cfg.agent
        self.bus.publish(k.robot(self.rid, "cmd_vel"), Twist(stamp, v, w), control=True)
        assert self.pose_source is not None
        self.bus.publish(
            k.robot(self.rid, "pose"),
            PoseEstimate(stamp, *pose, self.pose_source.covariance(), self.pose_source.name),
        )
        on_its_way = None if self.state in ("stale", "holding") else follow
        points = own_intent(stamp, pose, (v, w), on_its_way, self.cfg.robot, a.intent_horizon_s)
        self.bus.publish(
            k.robot(self.rid, "intent"),
            Intent(stamp, points, plan_id, follow.index if follow is not None else -1),
        )
        if stamp - self._last_status >= 1.0 / a.status_hz or self.state == "done":
            self._last_status = stamp
            n = len(follow.waypoints) if follow is not None else 0
            idx = follow.index if follow is not None else 0
            self.bus.publish(
                k.robot(self.rid, "status"),
                RobotStatus(
                    stamp,
                    self.state,
                    task,
                    idx / n if n else (1.0 if self.state == "done" else 0.0),
                    idx,
                    n,
                    self.distance_m,
                    sum(self.bus.decode_errors.values()),
                    follow.skipped if follow is not None else 0,
                    plan_id,
                    swept_pieces(follow, sweep_from),
                    self.time_s.copy(),
                ),
                control=True,
            )

    def publish_map(self, stamp: float) -> None:
        """Publish the map's changed tiles, at most ``agent.map_hz`` times per sim second."""
        if stamp - self._last_map < 1.0 / self.cfg.agent.map_hz:
            return
        assert self.pose_source is not None
        snapshot = self.pose_source.occupancy()
        if snapshot is None:
            return
        self._last_map = stamp
        self._map_snapshot = snapshot
        if self.state_dir is not None and stamp - self._last_save >= self.cfg.agent.state_save_s:
            self._last_save = stamp
            try:
                save_state(self.state_dir, snapshot, self.pose_source.pose(), stamp)
            except OSError as e:
                log.warning(
                    "%s: could not save its map and pose to %s: %s", self.rid, self.state_dir, e
                )
        update = self._patches.update(snapshot)
        if update.full or update.patches:
            self._map_seq += 1
            msg = _map_message(stamp, self._map_seq, self.cfg.slam.map_tile, update)
            self.bus.publish(self.keys.robot(self.rid, "map"), msg)

    def run(self) -> None:
        for loop in (self.heartbeat_loop, self.bid_loop):
            threading.Thread(target=loop, name=loop.__name__, daemon=True).start()
        self.fetch_plan()
        while not self.stop.is_set():
            try:
                scan = self.scans.get(timeout=0.1)
            except queue.Empty:
                continue
            self.step(scan)
            self.publish_map(scan.stamp)
            self.save_pose(scan.stamp)

    def save_pose(self, stamp: float) -> None:
        """With a state directory, write the pose every ``agent.pose_save_s`` (sim time) once the
        robot knows where it is, so a respawn searches a small window around it."""
        src = self.pose_source
        if (
            self.state_dir is None
            or src is None
            or not src.localized
            or stamp - self._last_pose_save < self.cfg.agent.pose_save_s
        ):
            return
        self._last_pose_save = stamp
        try:
            save_pose(self.state_dir, src.pose(), stamp)
        except OSError as e:
            log.warning("%s: could not save its pose to %s: %s", self.rid, self.state_dir, e)


def respawn_window(cfg: FleetConfig) -> tuple[float, float]:
    """How far (± m, ± rad) a robot's body can be from the pose its agent last saved: it drove
    on for at most ``agent.pose_save_s`` plus the simulator's ``max_lag_s`` at top speed, then
    braked to a stop at its acceleration limits (v²/2a), plus a margin for the estimate's own
    error."""
    r = cfg.robot
    seconds = cfg.agent.pose_save_s + cfg.sim.max_lag_s
    xy = r.max_vel_x * seconds + r.max_vel_x**2 / (2 * r.acc_lim_x) + RESPAWN_MARGIN_XY
    theta = (
        r.max_vel_theta * seconds
        + r.max_vel_theta**2 / (2 * r.acc_lim_theta)
        + RESPAWN_MARGIN_THETA
    )
    return xy, min(theta, math.pi)


def _map_message(stamp: float, seq: int, tile: int, update: MapUpdate) -> MapPatches:
    return MapPatches.pack(
        stamp,
        seq,
        update.full,
        update.shape,
        update.resolution,
        update.origin,
        tile,
        [(p.row, p.col, p.data) for p in update.patches],
    )
