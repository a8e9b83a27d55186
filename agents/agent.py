"""The robot process: a thin shell around the control step (:mod:`agents.control`).

It knows only what a real robot knows: its scans, its odometry, the sim clock and what the
coordinator sends. Each scan triggers one control step, called with what the agent has heard
(odometry, the plan it drives, the other robots' intents); the shell publishes what the step
returns — the cmd_vel it publishes carries that scan's stamp, which is how the simulator knows
the agent has kept up — and measures the latency of its commands against the sim clock, from
which the next step predicts its pose. The shell keeps the bus, the threads and the lock, the
plan it drives (:class:`agents.control.Drive`), and its map, published and saved to the state
directory by :class:`agents.map_keeper.MapKeeper`.

It takes part in the market (:mod:`agents.market`): it bids on called tasks from its own pose
and commitments, acknowledges the queue it is awarded, drives only plans for tasks it holds,
and reports the pieces of its task it has swept. A thread of its own sends a heartbeat on wall
time, so a hung agent falls silent. With a state directory it saves its SLAM map and pose every
``agent.state_save_s`` and its pose alone every ``agent.pose_save_s``; started with
``respawn`` it takes over its robot's body where it stands, finds itself in the saved map
(first within ``respawn_window`` of the saved pose), and bids only once it has.

What it takes is judged first (:mod:`agents.receivers`): its clock is the simulator's, believed
one clock step at a time from clock messages and scans; odometry and scans stamped past it, a
scan that is not its lidar's, odometry its robot cannot have driven, and intents of robots not
in the job or that no robot could announce are dropped and counted (the count goes out in its
status beside the malformed one). A message whose handling raises is dropped, never the process:
a scan whose control step fails is answered with a stop, so the simulator's lockstep goes on.
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

from agents.bidding import Bidder
from agents.control import ControlParams, ControlState, Drive, Heard, control
from agents.map_keeper import MapKeeper
from agents.market import MarketClient
from agents.placing import UnplacedSlamPose
from agents.pose_source import OdometryPose, PoseSource, RelocalizingSlamPose, SlamPose
from agents.receivers import Receivers
from agents.slam.persistence import SavedState, load_state, state_path
from fleet.bus import Bus
from fleet.floor_map import unpack_grid
from fleet.params import FleetConfig
from fleet.protocol import (
    AuctionCall,
    Award,
    AwardAck,
    BatteryState,
    Bids,
    Clock,
    Docks,
    Heartbeat,
    Intent,
    LaserScan,
    MapPatches,
    Odometry,
    Placement,
    Plan,
    Request,
    SpawnReply,
    SpawnRequest,
    Twist,
)
from planners.grid import GridMap

log = logging.getLogger("agent")

# The latency of a command (sim time from its scan to the clock when it is sent) is smoothed
# with this gain. At --speed 0 the simulator waits for each answer, so it is 0; in real time
# it is the time a control step takes.
LATENCY_GAIN = 0.2
ODOM_WAIT_S = 0.02
MAX_LATENCY_S = 0.5
# how long the end of the control loop waits for the heartbeat and bid loops to end (wall s)
LOOPS_END_S = 2.0
# a respawned robot's SLAM estimate of where it stood is itself this far off at most
RESPAWN_MARGIN_XY = 0.05
RESPAWN_MARGIN_THETA = 0.1


class Agent:
    """One robot's process around its control step; see the module's docstring."""

    def __init__(
        self,
        bus: Bus,
        rid: str,
        cfg: FleetConfig,
        state_dir: Path | None = None,
        unknown_start: bool = False,
    ) -> None:
        self.bus = bus
        # started with no known pose: mapped in its own frame until the fleet places it
        self.unknown_start = unknown_start
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
        # the battery sensor's last reading, if any (robot.battery on)
        self.battery: BatteryState | None = None
        self.latency_s = 0.0
        self.drive = Drive()
        # the latest intent of each other robot
        self.peers: dict[str, Intent] = {}
        self.params = ControlParams.of(rid, cfg)
        self.control_state = ControlState()
        # its sim clock, and what it believes of each message it takes
        self.rx = Receivers.of(rid, cfg, bus.drop_implausible)
        self.maps = MapKeeper(bus, rid, cfg, state_dir)
        self.market = MarketClient(
            rid,
            cfg.agent.transit_speed,
            cfg.robot.radius,
            cfg.slam.occupied_threshold,
            cfg.slam.free_threshold,
            cfg.robot.battery,
        )
        self._told_no_floor = False
        self.bidder = Bidder(bus, rid, self._answer, self.stop)

    def spawn(
        self, start: tuple[float, float, float], respawn: bool = False, timeout: float = 30.0
    ) -> None:
        """Ask the simulator to place the robot (with ``respawn``: to hand over the body the
        robot left in the world, and load the saved map and pose from the state directory);
        retry until it answers or ``timeout`` passes.

        The subscriptions come first: the simulator sends the first scan right after placing
        the robot and then holds its clock until that scan is answered."""
        saved = saved_state(self.state_dir, respawn, self.unknown_start)
        start = saved.pose if saved is not None else start
        self._subscribe()
        request = SpawnRequest(self.rid, *start, rejoin=respawn, own_frame=self.unknown_start)
        reply = request_spawn(self.bus, request, timeout)
        if reply.stamp >= 0:
            self.rx.start(reply.stamp)
        spawned = (reply.x, reply.y, reply.theta)
        source = pose_source_for(self.cfg, saved, spawned, self.unknown_start)
        with self.lock:
            self.control_state = ControlState(localized=source.localized)
            self.pose_source = source
        log.info("%s %s", self.rid, how_spawned(saved, spawned, source))

    @property
    def clock(self) -> float:
        """The sim time the agent believes (:class:`agents.receivers.Receivers`)."""
        return self.rx.now

    def _subscribe(self) -> None:
        k = self.keys
        # peers are in the job by their liveliness tokens, heard before their intents
        self.bus.watch_alive("agent", self.rx.joined, self.rx.left)
        self.bus.subscribe(k.robot(self.rid, "odom"), Odometry, self._on_odom)
        self.bus.subscribe(k.robot(self.rid, "battery"), BatteryState, self._on_battery)
        self.bus.subscribe(k.robot(self.rid, "scan"), LaserScan, self._on_scan)
        self.bus.subscribe(k.clock(), Clock, self._on_clock)
        self.bus.subscribe(k.plan(self.rid), Plan, self._on_plan)
        self.bus.subscribe(k.all_robots("intent"), Intent, self._on_intent)
        self.bus.subscribe(k.call(), AuctionCall, self.bidder.on_call)
        self.bus.subscribe(k.award(self.rid), Award, self._on_award)
        self.bus.serve(k.robot(self.rid, "map"), Request, self._on_map_request)
        if self.unknown_start:
            self.bus.subscribe(k.placement(self.rid), Placement, self._on_placement)

    def _on_placement(self, _key: str, msg: Placement) -> None:
        """The coordinator placed this robot's map on the fleet's: carry it into that frame."""
        with self.lock:
            source, pose = self.pose_source, None
            if isinstance(source, UnplacedSlamPose) and msg.robot == self.rid:
                pose = source.place(msg.x, msg.y, msg.theta)
        if pose is not None:
            log.info("%s placed on the fleet's map at (%.2f, %.2f, %.2f)", self.rid, *pose)

    def fetch_plan(self) -> None:
        """Late joiners ask the coordinator for their current plan instead of waiting for one."""
        try:
            plan = self.bus.request(self.keys.plan(self.rid), Request(self.rid), Plan, timeout=1.0)
        except (TimeoutError, RuntimeError):
            return
        self._on_plan("", plan)

    # ---- bus callbacks ------------------------------------------------------------------

    def _on_odom(self, key: str, msg: Odometry) -> None:
        if not self.rx.odometry(key, msg):
            return
        with self.lock:
            if self.pose_source is None:
                return
            self.pose_source.on_odometry(msg)
            self.odom_stamp = msg.stamp
            self.velocity = (msg.v, msg.w)

    def _on_battery(self, key: str, msg: BatteryState) -> None:
        if self.rx.battery(key, msg):
            self.battery = msg  # one reference, replaced whole

    def _on_scan(self, key: str, msg: LaserScan) -> None:
        if not self.rx.scan(key, msg):
            return
        with contextlib.suppress(queue.Empty):
            self.scans.get_nowait()
        self.scans.put_nowait(msg)

    def _on_intent(self, key: str, msg: Intent) -> None:
        rid = self.keys.robot_of(key)
        if rid != self.rid and self.rx.intent(key, rid, msg):
            with self.lock:
                self.peers[rid] = msg

    def _on_clock(self, key: str, msg: Clock) -> None:
        self.rx.on_clock(key, msg.stamp)

    def _on_plan(self, key: str, msg: Plan) -> None:
        if not self.rx.plan(key, msg):
            return
        with self.lock:
            if msg.plan_id == self.drive.plan_id:
                self._cut_plan(msg)
                return
            if not self.market.holds(msg.task) and not msg.errand:
                return
            self.drive = Drive.of(msg, self.market.queue, self.params.follow)
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
        follow = self.drive.follow
        if follow is None or len(msg.waypoints) >= len(follow.waypoints):
            return
        self.drive = self.drive.cut(msg, self.market.queue, self.params.follow)
        log.info("%s: plan %d now ends after %s", self.rid, msg.plan_id, self.drive.chain[-1])

    def _on_award(self, _key: str, msg: Award) -> None:
        with self.lock:
            taken = self.market.on_award(msg)
            follow = self.drive.follow
            driving = follow is not None and not follow.done
            held = self.drive.errand or any(map(self.market.holds, self.drive.chain))
            dropped = taken and driving and not held
            if dropped:
                self.drive = dataclasses.replace(self.drive, follow=None, task="")
            seq = self.market.seq
        self.bus.publish(self.keys.ack(self.rid), AwardAck(self.clock, seq, self.rid), True)
        if taken:
            log.info("%s: award %d, queue %s", self.rid, seq, " ".join(msg.tasks) or "empty")
        if dropped:
            log.warning("%s: its task went to another robot; stopping it", self.rid)

    @property
    def ready(self) -> bool:
        """Whether the robot may take work: it knows where it is."""
        src = self.pose_source
        return src is not None and src.localized

    def _answer(self, call: AuctionCall) -> Bids | None:
        """This robot's bids on ``call`` (:class:`agents.bidding.Bidder` publishes them); None
        for a call whose lot arrays disagree in length (dropped as implausible), before it
        knows where it is, or for a round that does not name it: one called before
        the coordinator heard it was ready (just placed, or found in its saved map) would
        refuse its bids as from a robot not in the market."""
        if not call.consistent():
            self.bus.drop_implausible(
                self.keys.call(), "coordinator", "lot arrays of unequal length"
            )
            return None
        if not self.ready or (call.bidders and self.rid not in call.bidders):
            return None
        if not self.market.has_floor:
            self._fetch_floor()
        with self.lock:
            assert self.pose_source is not None
            self.market.use_map(self.maps.snapshot)
            drive = self.drive
            commitment = self.market.commitment(
                self.pose_source.pose(), drive.follow, list(drive.chain), drive.chain_time_s
            )
            return self.market.bids(call, commitment, self.battery)

    def _fetch_floor(self) -> None:
        try:
            floor, docks = fetch_floor(self.bus, self.rid)
        except (TimeoutError, RuntimeError, ValueError) as e:
            if not self._told_no_floor:  # an exploring fleet's coordinator has none
                log.warning("%s: no floor plan (%s); pricing on its own map", self.rid, e)
            self._told_no_floor = True
            if not len(self.market.docks):  # exploring with batteries, it serves the docks
                docks = fetch_docks(self.bus, self.rid)
                with self.lock:
                    self.market.docks = docks
            return
        with self.lock:
            self.market.use_floor(floor)
            self.market.docks = docks

    def heartbeat_loop(self) -> None:
        """A heartbeat every 1 / ``agent.heartbeat_hz`` wall seconds, whatever sim time does."""
        period = 1.0 / self.cfg.agent.heartbeat_hz
        seq = 0
        while not self.stop.wait(period):
            seq += 1
            try:
                beat = Heartbeat(self.clock, seq, self.ready)
                self.bus.publish(self.keys.robot(self.rid, "heartbeat"), beat)
            except Exception:
                self.bus.handler_failed("heartbeat")

    def _on_map_request(self, _req: Request) -> MapPatches:
        return self.maps.whole(self.clock)

    # ---- control ------------------------------------------------------------------------

    def step(self, scan: LaserScan) -> Twist:
        """One control step on a fresh scan (:func:`agents.control.control`): what the agent
        has heard goes in, the outputs are published."""
        # The odometry of the scan's moment is sent first but on another stream; give it a
        # moment to arrive, so SLAM pairs the scan with it (see SlamPose).
        deadline = time.monotonic() + ODOM_WAIT_S
        while self.odom_stamp < scan.stamp - 1e-9 and time.monotonic() < deadline:
            time.sleep(0.001)
        # the lock is held throughout: the pose source is fed odometry on another thread
        with self.lock:
            assert self.pose_source is not None
            heard = Heard(
                scan,
                self.odom_stamp,
                self.velocity,
                self.drive,
                dict(self.peers),
                self.latency_s,
                *self.bus.dropped(),
                self.battery,
            )
            self.control_state, out = control(
                heard, self.control_state, self.params, self.pose_source
            )
            if out.follow is not heard.drive.follow:
                self.drive = dataclasses.replace(self.drive, follow=out.follow)
            own_frame = self.pose_source.own_frame
        for level, text in out.notes:
            log.log(level, "%s %s", self.rid, text)
        lag = min(max(self.clock - scan.stamp, 0.0), MAX_LATENCY_S)
        self.latency_s += LATENCY_GAIN * (lag - self.latency_s)
        k = self.keys
        self.bus.publish(k.robot(self.rid, "cmd_vel"), out.cmd_vel, control=True)
        # a pose in the robot's own frame would stand it somewhere else on everyone's map
        if not own_frame:
            self.bus.publish(k.robot(self.rid, "pose"), out.pose)
            self.bus.publish(k.robot(self.rid, "intent"), out.intent)
        if out.status is not None:
            self.bus.publish(k.robot(self.rid, "status"), out.status, control=True)
        return out.cmd_vel

    def run(self) -> None:
        """The control loop until ``stop``, with the heartbeat and bid loops beside it; it
        returns once they have ended too, so that the caller may close the bus (a heartbeat
        sent as the session closed raised: a traceback in the agent's log at a run's end)."""
        loops = [
            threading.Thread(target=loop, name=loop.__name__, daemon=True)
            for loop in (self.heartbeat_loop, self.bidder.loop)
        ]
        for thread in loops:
            thread.start()
        try:
            self.fetch_plan()
            while not self.stop.is_set():
                try:
                    scan = self.scans.get(timeout=0.1)
                except queue.Empty:
                    continue
                self.handle(scan)
        finally:
            self.stop.set()
            for thread in loops:
                thread.join(LOOPS_END_S)

    def handle(self, scan: LaserScan) -> None:
        """One scan: the control step, then the map. A step that raises costs this scan, which
        is answered with a stop (the simulator holds its clock until the scan is answered)."""
        try:
            self.step(scan)
        except Exception:
            self.bus.handler_failed("robot/*/scan")
            with contextlib.suppress(Exception):
                stop = Twist(scan.stamp, 0.0, 0.0)
                self.bus.publish(self.keys.robot(self.rid, "cmd_vel"), stop, control=True)
            return
        try:
            assert self.pose_source is not None
            self.maps.publish(scan.stamp, self.pose_source)
            self.maps.save_pose(scan.stamp, self.pose_source)
        except Exception:
            self.bus.handler_failed("robot/*/map")


def request_spawn(bus: Bus, req: SpawnRequest, timeout: float) -> SpawnReply:
    """The simulator's answer to ``req``, asked again until it answers or ``timeout`` (wall s)
    passes; ValueError when it refuses."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            reply = bus.request(bus.keys.sim_spawn(), req, SpawnReply, timeout=2.0)
            break
        except (TimeoutError, RuntimeError) as e:
            if time.monotonic() > deadline:
                raise TimeoutError(f"no simulator answered the spawn request: {e}") from None
            time.sleep(0.2)
    if not reply.ok:
        raise ValueError(f"spawn refused: {reply.error}")
    return reply


def fetch_floor(bus: Bus, rid: str) -> tuple[GridMap, np.ndarray]:
    """The coordinator's floor plan and its docks (TimeoutError, RuntimeError or ValueError
    when it serves none: an exploring coordinator)."""
    msg = bus.request(bus.keys.floor_map(), Request(rid), MapPatches, 1.0)
    return unpack_grid(msg), fetch_docks(bus, rid)


def fetch_docks(bus: Bus, rid: str) -> np.ndarray:
    """Where a robot stands on each dock (K, 2), as the coordinator serves them; none when it
    serves none (an exploring coordinator)."""
    try:
        msg = bus.request(bus.keys.docks(), Request(rid), Docks, 1.0)
    except (TimeoutError, RuntimeError, ValueError):
        return np.zeros((0, 2))
    return np.asarray(msg.poses, dtype=float).reshape(-1, 3)[:, :2]


def saved_state(state_dir: Path | None, respawn: bool, unknown_start: bool) -> SavedState | None:
    """What a respawned robot reloads from ``state_dir``; None for a robot started afresh, or
    for one started with no known pose that was never placed (it saved nothing, and waits to
    be placed again)."""
    if not respawn:
        return None
    if state_dir is None:
        raise ValueError("a respawn needs the state directory the robot saved to")
    if unknown_start and not state_path(state_dir).exists():
        return None
    return load_state(state_dir)


def pose_source_for(
    cfg: FleetConfig,
    saved: SavedState | None,
    spawned: tuple[float, float, float],
    unknown_start: bool,
) -> PoseSource:
    """The pose source of a robot spawned at ``spawned``: a respawned robot's (``saved`` its
    state) first finds the robot in its saved map, one with no known start maps in its own
    frame until placed, others start at the spawn pose (SLAM, or odometry alone)."""
    lidar = cfg.lidar
    if saved is not None:
        return RelocalizingSlamPose(
            cfg.slam, saved, lidar.range_min, lidar.range_max, near=respawn_window(cfg)
        )
    if unknown_start:
        return UnplacedSlamPose(cfg.slam, lidar.range_min, lidar.range_max)
    if cfg.agent.pose_source == "odometry":
        return OdometryPose(spawned)
    return SlamPose(cfg.slam, spawned, lidar.range_min, lidar.range_max)


def how_spawned(
    saved: SavedState | None, spawned: tuple[float, float, float], source: PoseSource
) -> str:
    """The log line's words for how a robot came into the world, and where its pose comes
    from."""
    if saved is not None:
        x, y, theta = saved.pose
        at = f"({x:.2f}, {y:.2f}, {theta:.2f})"
        return f"took over its body; finding itself in its saved map near {at}"
    if source.own_frame:
        return "spawned with no known pose, pose from slam in its own frame; waiting to be placed"
    x, y, theta = spawned
    return f"spawned at ({x:.2f}, {y:.2f}, {theta:.2f}), pose from {source.name}"


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
