"""The simulator process: steps :class:`SimCore` and talks to the fleet over Zenoh.

Time: sim time advances at ``speed`` × wall time (``speed`` 0: as fast as the live agents
answer; in real time while none is live), but never more than ``max_lag_s`` past the newest
sensor stamp each live agent has answered with a cmd_vel; and not at all while the
coordinator's newest state says it is making its first plan (phase ``planning``, until it
publishes another or its liveliness token goes), so the robots start from rest when the plan
is ready and no sim time passes before it. An agent whose liveliness token
disappears, or that has been silent for ``agent_timeout_s`` of wall time
(``first_answer_timeout_s`` before its first answer, while it starts up), no longer holds the
clock back; its robot stops and stays in the world as an obstacle until it respawns.

A cmd_vel answers the newest scan its robot was sent, so it is dropped as implausible (counted,
its sender named) when it is stamped later than that scan, or asks for more than the robot's top
speeds (``robot.max_vel_x``, ``robot.max_vel_theta``) plus what it can gain in one scan period
at its acceleration limits; a command within that is clamped to the top speeds. No message
moves the lockstep past the newest scan.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from dataclasses import dataclass

import numpy as np

from fleet.bus import Bus
from fleet.params import FleetConfig
from fleet.protocol import (
    Clock,
    CoverageImage,
    CoverageSummary,
    FleetEvent,
    FleetState,
    Request,
    SpawnReply,
    SpawnRequest,
    TruthPose,
    Twist,
)
from fleet.world import World
from sim_server.core import SimCore, StepOutput
from sim_server.recorder import CarmenRecorder

log = logging.getLogger("sim")

IMAGE_PERIOD_S = 2.0


@dataclass
class AgentLink:
    """The simulator's view of a robot's agent. ``released_at`` is the sim time at which the
    agent was last let go (it left, or the coordinator lost it): a command stamped no later
    than that was sent before, and does not make the agent live again."""

    ack: float
    last_wall: float
    alive: bool = True
    answered: bool = False
    scanned: bool = False
    released_at: float = float("-inf")


class SimServer:
    def __init__(
        self,
        bus: Bus,
        world: World,
        cfg: FleetConfig,
        speed: float = 1.0,
        seed: int = 0,
        starts_xy: np.ndarray | None = None,
        recorder: CarmenRecorder | None = None,
    ) -> None:
        """``recorder``, when given, writes one robot's scans and odometry every step."""
        self.bus = bus
        self.recorder = recorder
        self.keys = bus.keys
        self.cfg = cfg
        self.speed = speed
        self.core = SimCore(world, cfg, seed=seed, starts_xy=starts_xy)
        self.lock = threading.Lock()
        self.links: dict[str, AgentLink] = {}
        # the stamp of the newest scan sent to each robot: what a command can answer
        self.scan_stamps: dict[str, float] = {}
        rp = cfg.robot
        scan_period = 1.0 / cfg.lidar.rate_hz
        self.max_v = rp.max_vel_x + rp.acc_lim_x * scan_period
        self.max_w = rp.max_vel_theta + rp.acc_lim_theta * scan_period
        self.stop = threading.Event()
        self.wall0 = time.monotonic()
        bus.subscribe(self.keys.all_robots("cmd_vel"), Twist, self._on_cmd)
        bus.serve(self.keys.sim_spawn(), SpawnRequest, self._on_spawn)
        bus.serve(self.keys.sim_report(), Request, lambda _req: self.summary())
        bus.serve(self.keys.coverage_image(), Request, lambda _req: self.coverage_image())
        bus.watch_alive("agent", lambda _rid: None, self._on_agent_left)
        bus.subscribe(self.keys.events(), FleetEvent, self._on_event)
        # while the coordinator makes its first plan the world waits for it
        self.planning = False
        bus.subscribe(self.keys.coord_state(), FleetState, self._on_state)
        bus.watch_alive("coordinator", lambda _ident: None, lambda _ident: self._planned())

    # ---- bus callbacks (zenoh threads) --------------------------------------------------

    def _on_cmd(self, key: str, msg: Twist) -> None:
        rid = self.keys.robot_of(key)
        with self.lock:
            link = self.links.get(rid)
            why = self._implausible(rid, msg)
            if not why and link is not None:
                if not link.alive and msg.stamp <= link.released_at:
                    # sent before the agent was let go, overtaken by its leaving (a dying agent's
                    # last command): taking it as a sign of life would refuse its respawn
                    return
                link.ack = max(link.ack, msg.stamp)
                link.last_wall = time.monotonic()
                link.alive = True
                link.answered = True
                self.core.set_cmd(rid, msg.v, msg.w)
        if why:
            self.bus.drop_implausible(key, rid, why)

    def _implausible(self, rid: str, msg: Twist) -> str:
        """Why a command for ``rid`` cannot be its agent's answer to a scan ("" if it can)."""
        if rid not in self.links or rid not in self.core.robots:
            return f"there is no robot {rid!r} in the world"
        newest = self.scan_stamps.get(rid)
        if newest is None or msg.stamp > newest + 1e-9:
            sent = "no scan" if newest is None else f"the newest scan sent at {newest:.3f} s"
            return f"stamped {msg.stamp:.3f} s, later than {sent}"
        if abs(msg.v) > self.max_v or abs(msg.w) > self.max_w:
            return f"v {msg.v:.3g} m/s, w {msg.w:.3g} rad/s: beyond what the robot can drive"
        return ""

    def _on_spawn(self, req: SpawnRequest) -> SpawnReply:
        with self.lock:
            present = req.robot in self.core.robots
            link = self.links.get(req.robot)
            if req.rejoin or present:
                why = ""
                if not present:
                    why = f"there is no {req.robot} in the world to rejoin"
                elif not req.rejoin:
                    why = (
                        f"{req.robot} is already in the world; an agent that takes over its body "
                        "starts with --respawn"
                    )
                elif link is not None and link.alive:
                    why = f"the agent of {req.robot} is still live"
                if why:
                    return SpawnReply(False, why, req.x, req.y, req.theta, self.core.t)
                self.links[req.robot] = AgentLink(self.core.t, time.monotonic())
                log.info("a new agent took over robot %s where it stood", req.robot)
                return SpawnReply(True, "", req.x, req.y, req.theta, self.core.t)
            try:
                x, y, th = self.core.add_robot(req.robot, (req.x, req.y, req.theta), req.own_frame)
            except ValueError as e:
                return SpawnReply(False, str(e), req.x, req.y, req.theta, self.core.t)
            self.links[req.robot] = AgentLink(self.core.t, time.monotonic())
            log.info("robot %s spawned at (%.2f, %.2f, %.2f)", req.robot, x, y, th)
            return SpawnReply(True, "", x, y, th, self.core.t)

    def _on_agent_left(self, rid: str) -> None:
        self._release(rid, "left")

    def _on_event(self, _key: str, msg: FleetEvent) -> None:
        # The coordinator's heartbeat watch notices a hung agent long before agent_timeout_s.
        if msg.kind == "lost":
            self._release(msg.robot, "was lost to the coordinator")

    def _on_state(self, _key: str, msg: FleetState) -> None:
        if msg.phase == "planning":
            with self.lock:
                self.planning = True
        else:
            self._planned()

    def _planned(self) -> None:
        """The coordinator has its plan (or is gone): the clock runs again, and the agents'
        silence is counted from now, since they had no scan to answer while it waited."""
        with self.lock:
            if not self.planning:
                return
            self.planning = False
            now = time.monotonic()
            for link in self.links.values():
                link.last_wall = max(link.last_wall, now)

    def _release(self, rid: str, why: str) -> None:
        """Stop waiting for ``rid``'s agent; its robot stops and stays where it is."""
        with self.lock:
            link = self.links.get(rid)
            if link is not None and link.alive:
                link.alive = False
                link.released_at = self.core.t
                self.core.set_cmd(rid, 0.0, 0.0)
                log.info("agent %s %s; its robot stops where it is", rid, why)

    # ---- main loop ----------------------------------------------------------------------

    def summary(self) -> CoverageSummary:
        with self.lock:
            return self._counted(self.core.summary(time.monotonic() - self.wall0))

    def _counted(self, summary: CoverageSummary) -> CoverageSummary:
        """``summary`` with the messages this process has dropped."""
        malformed, implausible = self.bus.dropped()
        return dataclasses.replace(summary, decode_errors=malformed, implausible=implausible)

    def coverage_image(self) -> CoverageImage:
        with self.lock:
            c = self.core.cleaning
            g = c.grid
            return CoverageImage(
                self.core.t,
                g.resolution,
                g.origin[0],
                g.origin[1],
                g.shape[0],
                g.shape[1],
                c.visits.reshape(-1).copy(),
                c.cleanable.reshape(-1).astype(np.uint8),
                # empty without side brushes: nothing to send
                c.side.reshape(-1).astype(np.uint8) if c.side_brush else np.zeros(0, np.uint8),
            )

    def _held_back(self, now: float) -> bool:
        """True when a live agent has not yet answered sensor data within the allowed lag."""
        sim = self.cfg.sim
        limit = self.core.t + self.core.dt - sim.max_lag_s
        for rid, link in self.links.items():
            if not link.alive or not link.scanned or rid not in self.core.robots:
                continue
            timeout = sim.agent_timeout_s if link.answered else sim.first_answer_timeout_s
            if now - link.last_wall > timeout:
                link.alive = False
                self.core.set_cmd(rid, 0.0, 0.0)
                log.warning(
                    "agent %s silent for %.1f s; no longer waiting for it",
                    rid,
                    now - link.last_wall,
                )
                continue
            if link.ack < limit - 1e-9:
                return True
        return False

    def _tick(self) -> tuple[StepOutput, int]:
        """One physics step, and what it tells the links; its output and the step count."""
        with self.lock:
            out = self.core.tick(time.monotonic() - self.wall0)
            for rid, msg in out.scans:
                self.scan_stamps[rid] = msg.stamp
                link = self.links.get(rid)
                if link is not None and not link.scanned:
                    # The first scan is the first thing to answer: hold the clock there.
                    link.scanned = True
                    link.ack = max(link.ack, msg.stamp - self.cfg.sim.max_lag_s)
            if self.recorder is not None:
                self.recorder.record(out.odometry, out.scans, self.core.truth)
            return out, self.core.steps

    def run(self) -> None:
        sim = self.cfg.sim
        clock_every = max(1, round(sim.physics_hz / sim.clock_hz))
        pace_wall, pace_sim = time.monotonic(), self.core.t
        waiting = False
        while not self.stop.is_set():
            now = time.monotonic()
            with self.lock:
                planning = self.planning
                held = planning or self._held_back(now)
                live = any(link.alive and r in self.core.robots for r, link in self.links.items())
            if held:
                if not waiting:
                    self.bus.publish(self.keys.clock(), Clock(self.core.t, self.speed, True))
                    waiting = True
                # the coordinator's plan takes seconds and wants the CPU; an agent answers fast
                time.sleep(0.01 if planning else 0.0005)
                pace_wall, pace_sim = time.monotonic(), self.core.t
                continue
            waiting = False
            speed = self.speed if self.speed > 0 or live else 1.0
            if speed > 0:
                ahead = (self.core.t - pace_sim) / speed - (now - pace_wall)
                if ahead > 0:
                    time.sleep(min(ahead, 0.05))
                    continue
                if ahead < -0.2:
                    pace_wall, pace_sim = now, self.core.t
            out, steps = self._tick()
            k = self.keys
            for c in out.collisions:
                log.warning(
                    "collision %s: %s %s at (%.2f, %.2f)", c.kind, c.robot, c.other, c.x, c.y
                )
                self.bus.publish(k.collisions(), c, control=True)
            for rid, msg in out.odometry:
                self.bus.publish(k.robot(rid, "odom"), msg)
            for rid, msg in out.batteries:
                self.bus.publish(k.robot(rid, "battery"), msg)
            for rid, msg in out.scans:
                self.bus.publish(k.robot(rid, "scan"), msg, control=True)
            for rid, (x, y, th) in out.truth.items():
                self.bus.publish(k.robot(rid, "truth"), TruthPose(self.core.t, x, y, th))
            if steps % clock_every == 0:
                self.bus.publish(k.clock(), Clock(self.core.t, self.speed, False))
            if out.summary is not None:
                self.bus.publish(k.coverage(), self._counted(out.summary))
