"""The agent's control step: one scan in, what to publish out, as one pipeline.

    scan -> pose -> obstacles -> command -> what to publish

- *pose*: the scan, with the returns off the peers cut out (:func:`agents.peers.cut_out`), goes
  to the pose source (:mod:`agents.pose_source`: the robot's own SLAM, or odometry);
- *obstacles*: the scan's points (:func:`scan_points`) and the discs the peers it gives way to
  will cover, by their intents (:func:`agents.peers.to_avoid`);
- *command*: stop while the odometry is stale or the robot does not know where it is; without
  a path to follow, keep clear of everyone (:func:`agents.follow.escape.keep_clear`); hold for
  the peers its plan's order of passage waits for (:func:`agents.passage.hold`); else follow the
  path (:func:`agents.follow.motion.follow_step`) from the pose predicted for when the command
  takes effect (:func:`agents.follow.motion.predict`);
- *what to publish*: cmd_vel (with the scan's stamp, which tells the simulator the agent has
  kept up), the pose, the intent, and at ``agent.status_hz`` (and when done) the status.

:func:`control` is a function of its arguments but for the pose source, which it feeds the
scan: SLAM's state, its map above all, lives there and is too large to copy each step. The
agent's shell (:class:`agents.agent.Agent`) calls it once per scan with what it has heard
(:class:`Heard`), keeps the state it returns and publishes the outputs. Time is sim time.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from agents.follow.escape import keep_clear
from agents.follow.motion import follow_step, predict
from agents.follow.state import FollowParams, FollowState, Situation
from agents.follow.track import tracked
from agents.market import Won, swept_pieces
from agents.passage import Holding, Waits, hold
from agents.peers import cut_out, own_intent, progress, to_avoid
from agents.pose_source import Located, Pose, PoseSource, locate
from agents.time_use import step_kind
from fleet.params import FleetConfig
from fleet.plan_chain import chain_of, chain_starts, current_task
from fleet.protocol import (
    ERRAND_KINDS,
    TIME_KINDS,
    BatteryState,
    Intent,
    LaserScan,
    Plan,
    PoseEstimate,
    RobotStatus,
    Twist,
)

MEDIAN_BEAMS = 5

# a line for the agent's log: its level and its text after the robot's id
Note = tuple[int, str]


@dataclass(frozen=True, eq=False)
class Drive:
    """The plan the robot drives, as the shell holds it: what the coordinator sent (plan id,
    task and kind, the waypoint where the sweep begins, the chain of tasks with where each
    begins and their time, the order of passage) and the follower's state along it (None: no
    path)."""

    plan_id: int = -1
    task: str = ""
    kind: str = "clean"
    sweep_from: int = 0
    chain: tuple[str, ...] = ()
    chain_starts: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int32))
    chain_time_s: float = 0.0
    waits: Waits = field(default_factory=Waits.none)
    follow: FollowState | None = None

    @property
    def errand(self) -> bool:
        """Whether the plan is an errand to a dock (``Plan.errand``), no work of the job."""
        return self.kind in ERRAND_KINDS

    @classmethod
    def of(cls, plan: Plan, queue: Sequence[Won], params: FollowParams) -> Drive:
        """A new plan, its chain timed by the robot's ``queue`` of won tasks; its sweeps (the
        waypoints after ``sweep_from``) tracked (:func:`agents.follow.track.tracked`)."""
        chain = tuple(chain_of(plan))
        return cls(
            plan.plan_id,
            plan.task,
            plan.kind,
            plan.sweep_from,
            chain,
            chain_starts(plan),
            sum(w.time_s for w in queue if w.id in chain),
            Waits.of(plan),
            tracked(plan.waypoints, plan.sweep_from, params) if len(plan.waypoints) else None,
        )

    def cut(self, plan: Plan, queue: Sequence[Won], params: FollowParams) -> Drive:
        """The same drive ending where ``plan``, this plan cut short, now ends: the follower
        drives on as before until there, braking into the new end."""
        assert self.follow is not None
        chain = tuple(chain_of(plan))
        return replace(
            self,
            chain=chain,
            chain_starts=chain_starts(plan),
            chain_time_s=sum(w.time_s for w in queue if w.id in chain),
            follow=replace(
                self.follow,
                waypoints=plan.waypoints,
                profile=tracked(plan.waypoints, plan.sweep_from, params).profile,
            ),
        )


@dataclass(frozen=True, eq=False)
class Heard:
    """What a control step is given: the scan, the stamp and velocity (v, ω) of the latest
    odometry, the plan being driven, each peer's latest intent, the latency of a command (sim
    s from its scan until it is sent) and how many messages the bus has dropped as malformed and
    as implausible, and the battery sensor's last reading (None without one)."""

    scan: LaserScan
    odom_stamp: float
    velocity: tuple[float, float]
    drive: Drive
    peers: Mapping[str, Intent]
    latency_s: float
    decode_errors: int
    implausible: int = 0
    battery: BatteryState | None = None


@dataclass(frozen=True, eq=False)
class ControlState:
    """What the control step carries from one scan to the next: the state it reports, its last
    command, the follower of a robot without work, where it holds for its peers, the distance
    driven and the time spent on each of ``TIME_KINDS``, when it last sent a status, and
    whether it knew where it was (and said that it cannot find itself)."""

    mode: str = "waiting"
    command: tuple[float, float] = (0.0, 0.0)
    idle: FollowState = field(default_factory=lambda: FollowState(np.zeros((0, 2))))
    holding: Holding = field(default_factory=Holding)
    last_xy: tuple[float, float] | None = None
    distance_m: float = 0.0
    time_s: tuple[float, ...] = (0.0,) * len(TIME_KINDS)
    last_status: float = -1e9
    localized: bool = True
    unlocalized_logged: bool = False


@dataclass(frozen=True)
class ControlParams:
    """The robot's id, which ranks it among its peers, and the follower's parameters."""

    robot_id: str
    follow: FollowParams

    @classmethod
    def of(cls, robot_id: str, cfg: FleetConfig) -> ControlParams:
        return cls(robot_id, FollowParams.of(cfg))


@dataclass(frozen=True, eq=False)
class Outputs:
    """What to publish, in this order (``status`` None: not due), the follower's state after
    the step, for the shell to keep with its plan, and the lines for its log."""

    cmd_vel: Twist
    pose: PoseEstimate
    intent: Intent
    status: RobotStatus | None
    follow: FollowState | None
    notes: tuple[Note, ...]


@dataclass(frozen=True)
class Command:
    """The command stage's answer: (v, ω), the state to report, the kind of step for the time
    accounting, the follower's state after it, and lines for the log."""

    v: float
    w: float
    mode: str
    kind: str
    follow: FollowState | None
    notes: tuple[Note, ...] = ()


def control(
    heard: Heard, state: ControlState, params: ControlParams, pose_source: PoseSource
) -> tuple[ControlState, Outputs]:
    """One control step on ``heard.scan``; see the module's docstring."""
    scan, agent, robot = heard.scan, params.follow.agent, params.follow.robot
    # scan -> pose
    for_slam = cut_out(scan, pose_source.pose(), heard.peers, agent.stale_after_s, robot)
    located = locate(pose_source, for_slam)
    state, notes = _moved(state, located)
    # -> obstacles: the scan's points; the peers' discs depend on the command's case
    obstacles = scan_points(located.pose, scan.ranges, scan.angle_min, scan.angle_increment)
    # -> command
    state, command = _command(heard, state, params, located, obstacles)
    state = _account(state, command, params.follow.dt)
    # -> what to publish
    return _outputs(heard, state, params, located, command, notes + command.notes)


def scan_points(
    pose: Pose, ranges: np.ndarray, angle_min: float, angle_increment: float
) -> np.ndarray:
    """World-frame obstacle points of a scan; each range is a 5-beam median to damp noise."""
    r = np.asarray(ranges, dtype=float)
    half = MEDIAN_BEAMS // 2
    padded = np.concatenate([r[-half:], r, r[:half]])
    windows = np.lib.stride_tricks.sliding_window_view(padded, MEDIAN_BEAMS)
    r = np.median(windows, axis=1)
    ok = np.isfinite(r)
    a = pose[2] + angle_min + angle_increment * np.nonzero(ok)[0]
    return np.column_stack([pose[0] + r[ok] * np.cos(a), pose[1] + r[ok] * np.sin(a)])


def _moved(state: ControlState, located: Located) -> tuple[ControlState, tuple[Note, ...]]:
    """The distance driven by the pose estimate, and whether the robot has just found itself
    (in its saved map, or placed on the fleet's); the jump of the estimate then is no drive."""
    pose = located.pose
    notes: tuple[Note, ...] = ()
    if located.localized and not state.localized:
        at = f"({pose[0]:.2f}, {pose[1]:.2f}, {pose[2]:.2f})"
        notes = ((logging.INFO, f"found itself at {at} on its map"),)
    distance = state.distance_m
    if state.last_xy is not None and located.localized == state.localized:
        distance += float(np.hypot(pose[0] - state.last_xy[0], pose[1] - state.last_xy[1]))
    moved = replace(state, localized=located.localized, last_xy=pose[:2], distance_m=distance)
    return moved, notes


def _command(
    heard: Heard,
    state: ControlState,
    params: ControlParams,
    located: Located,
    obstacles: np.ndarray,
) -> tuple[ControlState, Command]:
    """Stop (stale odometry, not localized), keep clear (no path; on its dock, stand), hold,
    or follow the path."""
    drive, agent, stamp, pose = heard.drive, params.follow.agent, heard.scan.stamp, located.pose
    follow = drive.follow
    if stamp - heard.odom_stamp > agent.stale_after_s:
        return state, Command(0.0, 0.0, "stale", "other", follow)
    if not located.localized:
        return _lost(state, located, follow)
    if follow is not None and follow.done and drive.kind == "dock":
        # on its dock: stepping aside for a peer would take it off the charger
        return state, Command(0.0, 0.0, "done", "idle", follow)
    if follow is None or follow.done:
        peers = to_avoid(params.robot_id, heard.peers, stamp, agent.stale_after_s, everyone=True)
        now = Situation(pose, heard.velocity, obstacles, peers)
        idle, result = keep_clear(state.idle, now, params.follow)
        mode = "done" if drive.plan_id >= 0 else "waiting"
        return replace(state, idle=idle), Command(result.v, result.w, mode, "idle", follow)
    holding, ahead, stop_at, notes = hold(
        state.holding,
        follow,
        np.array(pose[:2]),
        drive.plan_id,
        drive.waits,
        progress(heard.peers),
        stamp,
        agent,
    )
    state = replace(state, holding=holding)
    if ahead is not None:
        return state, Command(0.0, 0.0, "holding", "hold", ahead, notes)
    return state, _follow(heard, state, params, pose, obstacles, notes, stop_at)


def _lost(
    state: ControlState, located: Located, follow: FollowState | None
) -> tuple[ControlState, Command]:
    """Stand while the pose source looks for the robot; say once that it gave up."""
    if not located.failed:
        return state, Command(0.0, 0.0, "localizing", "other", follow)
    notes: tuple[Note, ...] = ()
    if not state.unlocalized_logged:
        state = replace(state, unlocalized_logged=True)
        text = f"cannot find itself in its saved map ({located.reason}); it stays out of the market"
        notes = ((logging.ERROR, text),)
    return state, Command(0.0, 0.0, "unlocalized", "other", follow, notes)


def _follow(
    heard: Heard,
    state: ControlState,
    params: ControlParams,
    pose: Pose,
    obstacles: np.ndarray,
    notes: tuple[Note, ...],
    stop_at: int = -1,
) -> Command:
    """Follow the path, giving way by rank to the peers the plan does not order it against:
    on a transit planned in space and time it keeps the order of passage with the peers it
    waits for (and that wait for it) instead, coming to rest on waypoint ``stop_at`` (the
    order of passage holds it before the next)."""
    drive, agent = heard.drive, params.follow.agent
    before = drive.follow
    assert before is not None
    if before.stop_at != stop_at:
        before = replace(before, stop_at=stop_at)
    ordered = frozenset(drive.waits.peer) if before.index <= drive.sweep_from else frozenset()
    peers = to_avoid(
        params.robot_id,
        heard.peers,
        heard.scan.stamp,
        agent.stale_after_s,
        everyone=False,
        skip=ordered,
    )
    everyone = to_avoid(
        params.robot_id, heard.peers, heard.scan.stamp, agent.stale_after_s, everyone=True
    )
    predicted = predict(pose, state.command, heard.latency_s)
    follow, result = follow_step(
        before, Situation(predicted, heard.velocity, obstacles, peers, everyone), params.follow
    )
    if follow.skipped > before.skipped:
        at = before.waypoints[before.index]
        short = float(np.hypot(pose[0] - at[0], pose[1] - at[1]))
        text = (
            f"gave up on waypoint {before.index} at ({at[0]:.2f}, {at[1]:.2f}): no progress "
            f"for {agent.give_up_after_s:.1f} s, {short:.3f} m short at "
            f"({pose[0]:.3f}, {pose[1]:.3f}, {pose[2]:.2f})"
        )
        notes += ((logging.WARNING, text),)
    kind = step_kind(before, follow, drive.sweep_from)
    if result is None:
        return Command(0.0, 0.0, "done", kind, follow, notes)
    mode = "driving" if result.admissible else "blocked"
    return Command(result.v, result.w, mode, kind, follow, notes)


def _account(state: ControlState, command: Command, dt: float) -> ControlState:
    """The command taken, and the step's time added to its kind."""
    time_s = list(state.time_s)
    time_s[TIME_KINDS.index(command.kind)] += dt
    return replace(state, mode=command.mode, command=(command.v, command.w), time_s=tuple(time_s))


def _outputs(
    heard: Heard,
    state: ControlState,
    params: ControlParams,
    located: Located,
    command: Command,
    notes: tuple[Note, ...],
) -> tuple[ControlState, Outputs]:
    """cmd_vel, pose, intent and, at ``agent.status_hz`` or when done, the status; the intent
    announces the path ahead only while the robot is on its way along it."""
    drive, agent = heard.drive, params.follow.agent
    stamp, pose, follow = heard.scan.stamp, located.pose, command.follow
    on_its_way = None if command.mode in ("stale", "holding") else follow
    points = own_intent(
        stamp, pose, state.command, on_its_way, params.follow.robot, agent.intent_horizon_s
    )
    intent = Intent(stamp, points, drive.plan_id, follow.index if follow is not None else -1)
    status = None
    if stamp - state.last_status >= 1.0 / agent.status_hz or command.mode == "done":
        state = replace(state, last_status=stamp)
        status = _status(heard, state, follow)
    outputs = Outputs(
        Twist(stamp, command.v, command.w),
        PoseEstimate(stamp, *pose, located.covariance, located.source),
        intent,
        status,
        follow,
        notes,
    )
    return state, outputs


def _status(heard: Heard, state: ControlState, follow: FollowState | None) -> RobotStatus:
    """The status, with the task the robot was on when the step began."""
    drive = heard.drive
    heading_for = None if drive.follow is None else drive.follow.index
    task = current_task(drive.chain, drive.chain_starts, heading_for) or drive.task
    n = len(follow.waypoints) if follow is not None else 0
    idx = follow.index if follow is not None else 0
    return RobotStatus(
        heard.scan.stamp,
        state.mode,
        task,
        idx / n if n else (1.0 if state.mode == "done" else 0.0),
        idx,
        n,
        state.distance_m,
        heard.decode_errors,
        follow.skipped if follow is not None else 0,
        drive.plan_id,
        swept_pieces(follow, drive.sweep_from),
        np.array(state.time_s),
        heard.implausible,
        -1.0 if heard.battery is None else heard.battery.percentage,
        heard.battery is not None and heard.battery.charging,
    )
