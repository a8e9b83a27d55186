"""The agent's control step without a bus: synthetic scans of a room in, what it would publish
out; holding for a peer, giving way by rank, keeping clear without work, stopping."""

from __future__ import annotations

import logging
import math
from dataclasses import replace

import numpy as np
from robots import ROBOT

from agents.control import ControlParams, ControlState, Drive, Heard, Outputs, control
from agents.follow.state import FollowParams
from agents.peers import path_intent
from agents.pose_source import OdometryPose
from fleet.params import AgentParams
from fleet.protocol import Intent, LaserScan, Plan
from planners.dwa import DWAParams
from planners.wall_follow import WallFollowParams
from sim_server.lidar import cast_scans

AGENT = AgentParams()
DT = 0.1
BEAMS = 360
INCREMENT = 2 * math.pi / BEAMS
# a 6 m square room
ROOM = np.array([[0, 0, 6, 0], [6, 0, 6, 6], [6, 6, 0, 6], [0, 6, 0, 0]], dtype=float)
START = (1.0, 3.0, 0.0)
LANE = [(1.0, 3.0), (5.0, 3.0)]


def _params(robot_id: str = "robot-1") -> ControlParams:
    return ControlParams(robot_id, FollowParams(DWAParams(), ROBOT, AGENT, WallFollowParams(), DT))


def _scan(
    stamp: float, pose: tuple[float, float, float], discs: np.ndarray | None = None
) -> LaserScan:
    """A noiseless scan of the room from ``pose``, with ``discs`` (x, y, r) in it."""
    discs = np.zeros((0, 3)) if discs is None else discs
    angles = -math.pi + INCREMENT * np.arange(BEAMS)
    ranges = cast_scans(np.array([pose[:2]]), np.array([pose[2]]), angles, ROOM, discs, 8.0)[0]
    return LaserScan(stamp, -math.pi, INCREMENT, 0.1, 8.0, ranges.astype(np.float32))


def _plan(waits: tuple[list, list, list, list] = ([], [], [], []), sweep_from: int = 0) -> Plan:
    at, peers, plans, passed = waits
    return Plan(
        0.0,
        3,
        "t01",
        np.array(LANE),
        sweep_from,
        wait_at=np.array(at, dtype=np.int32),
        wait_for=peers,
        wait_plan=np.array(plans, dtype=np.int32),
        wait_passed=np.array(passed, dtype=np.int32),
    )


def _heard(
    stamp: float,
    drive: Drive,
    peers: dict[str, Intent] | None = None,
    velocity: tuple[float, float] = (0.0, 0.0),
    odom_stamp: float | None = None,
) -> Heard:
    return Heard(
        _scan(stamp, START),
        stamp if odom_stamp is None else odom_stamp,
        velocity,
        drive,
        peers or {},
        0.0,
        0,
    )


def _step(
    heard: Heard, state: ControlState | None = None, robot_id: str = "robot-1"
) -> tuple[ControlState, Outputs]:
    return control(heard, state or ControlState(), _params(robot_id), OdometryPose(START))


def _crossing(stamp: float, plan_id: int = -1, waypoint: int = -1) -> Intent:
    """A peer's intent: it drives across the lane 0.6 m ahead of the robot."""
    ahead = np.array([[1.6, 4.0]])
    return Intent(
        stamp, path_intent(np.array([1.6, 2.2]), ahead, 0.3, stamp, 2.0), plan_id, waypoint
    )


def test_a_step_follows_the_plan_and_says_what_to_publish() -> None:
    drive = Drive.of(_plan(), [], _params().follow)
    state, out = _step(_heard(10.0, drive))
    assert (
        out.cmd_vel.stamp == 10.0
        and out.cmd_vel.v > 0
        and out.cmd_vel.v <= ROBOT.acc_lim_x * DT + 1e-9
    )
    assert (out.pose.x, out.pose.y, out.pose.theta) == START and out.pose.source == "odometry"
    # the intent announces the lane ahead, not the slow start
    assert out.intent.plan_id == 3 and out.intent.waypoint == 1
    assert np.allclose(out.intent.points[:, 2], 3.0) and out.intent.points[-1, 1] > 1.4
    assert out.status is not None and out.status.state == "driving" and out.status.task == "t01"
    assert out.follow is not None and out.follow.index == 1
    assert state.command == (out.cmd_vel.v, out.cmd_vel.w) and state.mode == "driving"
    # the status goes out at agent.status_hz: not again a scan later
    _, later = _step(_heard(10.1, replace(drive, follow=out.follow)), state)
    assert later.status is None


def test_a_robot_holds_for_the_peer_its_plan_waits_for_then_drives_on() -> None:
    """Its plan lets it head for waypoint 1 only once robot-0 has reached waypoint 1 of its
    plan 7 (Hönig et al. 2019); robot-0 outranks it, but the plan orders them instead."""
    drive = Drive.of(_plan(([1], ["robot-0"], [7], [1])), [], _params().follow)
    behind = {"robot-0": _crossing(10.0, plan_id=7, waypoint=1)}
    state, out = _step(_heard(10.0, drive, behind))
    assert (out.cmd_vel.v, out.cmd_vel.w) == (0.0, 0.0)
    assert out.status is not None and out.status.state == "holding"
    assert out.notes == ((logging.INFO, "holds before waypoint 1 for robot-0"),)
    assert np.allclose(out.intent.points[:, 1:], START[:2])  # it announces standing still
    assert state.holding.at == (3, 1, 10.0)
    assert out.follow is not None and out.follow.index == 1
    # robot-0 heads past its waypoint 1: the robot drives on
    passed = {"robot-0": _crossing(10.1, plan_id=7, waypoint=2)}
    state, out = _step(_heard(10.1, replace(drive, follow=out.follow), passed), state)
    assert out.cmd_vel.v > 0 and state.mode == "driving" and state.holding.at is None


def test_holding_is_given_up_after_hold_max_s() -> None:
    drive = Drive.of(_plan(([1], ["robot-0"], [7], [1])), [], _params().follow)
    state, out = _step(_heard(10.0, drive))  # robot-0 not heard yet: waited for
    assert state.mode == "holding"
    late = 10.0 + AGENT.hold_max_s + 0.1
    state, out = _step(_heard(late, replace(drive, follow=out.follow)), state)
    assert state.mode == "driving" and out.notes[0][0] == logging.WARNING
    assert state.holding.given_up == frozenset({(3, 1)})


def test_on_a_transit_a_robot_keeps_the_order_of_passage_not_the_rank() -> None:
    """Its transit (sweep_from past the lane) orders it after robot-0's waypoint 1, which
    robot-0 has passed: it drives on across robot-0's intent instead of giving way to it by
    rank. The same transit without that order gives way to robot-0 as to any peer above it."""
    cruising = (0.3, 0.0)
    crossing = {"robot-0": _crossing(10.0, plan_id=7, waypoint=2)}
    ordered = Drive.of(
        _plan(([1], ["robot-0"], [7], [1]), sweep_from=len(LANE)), [], _params().follow
    )
    unordered = Drive.of(_plan(sweep_from=len(LANE)), [], _params().follow)
    alone = _step(_heard(10.0, unordered, velocity=cruising))[1].cmd_vel
    keeps_order = _step(_heard(10.0, ordered, crossing, cruising))
    gives_way = _step(_heard(10.0, unordered, crossing, cruising))[1].cmd_vel
    assert keeps_order[0].mode == "driving"
    assert (keeps_order[1].cmd_vel.v, keeps_order[1].cmd_vel.w) == (alone.v, alone.w)
    assert gives_way.v < alone.v - 0.02


def test_a_robot_gives_way_to_a_peer_ranked_above_it_and_not_to_one_below() -> None:
    """Erdmann and Lozano-Pérez's priorities on the robots' intents: robot-1 slows for robot-0
    crossing ahead of it, and drives on as if robot-2 crossing there were not there."""
    drive = Drive.of(_plan(), [], _params().follow)
    cruising = (0.3, 0.0)
    alone = _step(_heard(10.0, drive, velocity=cruising))[1].cmd_vel
    gives_way = _step(
        _heard(10.0, drive, {"robot-0": _crossing(10.0)}, cruising), robot_id="robot-1"
    )[1].cmd_vel
    keeps_on = _step(
        _heard(10.0, drive, {"robot-2": _crossing(10.0)}, cruising), robot_id="robot-1"
    )[1].cmd_vel
    assert gives_way.v < alone.v - 0.02
    assert (keeps_on.v, keeps_on.w) == (alone.v, alone.w)


def test_a_robot_without_work_steps_aside_from_anyone() -> None:
    """Without a plan it keeps clear of every peer, ranked above it or not."""
    coming = {"robot-9": _crossing(10.0)}
    through = Intent(
        10.0, path_intent(np.array([0.4, 3.0]), np.array([[3.0, 3.0]]), 0.3, 10.0, 2.0)
    )
    state, out = _step(_heard(10.0, Drive(), {"robot-9": through}))
    assert out.status is not None and out.status.state == "waiting"
    assert (out.cmd_vel.v, out.cmd_vel.w) != (0.0, 0.0) and state.idle.escape_m > 0
    state, out = _step(_heard(10.0, Drive(), coming))
    assert (out.cmd_vel.v, out.cmd_vel.w) == (0.0, 0.0)  # one passing at a distance: stands


def test_stale_odometry_stops_the_robot() -> None:
    drive = Drive.of(_plan(), [], _params().follow)
    heard = _heard(10.0, drive, velocity=(0.3, 0.0), odom_stamp=10.0 - AGENT.stale_after_s - 0.1)
    state, out = _step(heard)
    assert (out.cmd_vel.v, out.cmd_vel.w) == (0.0, 0.0)
    assert out.status is not None and out.status.state == "stale"
    assert out.follow is drive.follow
    assert state.time_s[-1] == DT  # "other"


def test_the_scan_slam_sees_has_the_peers_cut_out() -> None:
    """The returns off a peer's body, where its intent puts it, never reach the pose source;
    the obstacles the follower sees still hold them."""

    class Recording(OdometryPose):
        def on_scan(self, msg: LaserScan) -> None:
            self.seen = msg

    source = Recording(START)
    peer = Intent(10.0, path_intent(np.array([2.0, 3.0]), np.zeros((0, 2)), 0.0, 10.0, 2.0))
    heard = replace(
        _heard(10.0, Drive(), {"robot-0": peer}),
        scan=_scan(10.0, START, np.array([[2.0, 3.0, ROBOT.radius]])),
    )
    control(heard, ControlState(), _params(), source)
    ahead = BEAMS // 2  # the beam straight ahead, at the peer
    assert heard.scan.ranges[ahead] < 1.0 and math.isnan(source.seen.ranges[ahead])
    assert np.isfinite(source.seen.ranges).sum() > 0.9 * BEAMS


def test_a_respawned_robot_stands_until_it_finds_itself() -> None:
    class Lost(OdometryPose):
        localized = False
        failed = True
        reason = "attempt 3: near: no match"

    drive = Drive.of(_plan(), [], _params().follow)
    state = ControlState(localized=False)
    state, out = control(_heard(10.0, drive), state, _params(), Lost(START))
    assert state.mode == "unlocalized" and (out.cmd_vel.v, out.cmd_vel.w) == (0.0, 0.0)
    assert out.notes[0][0] == logging.ERROR and "attempt 3" in out.notes[0][1]
    state, out = control(_heard(10.1, drive), state, _params(), Lost(START))
    assert out.notes == ()  # said once
    state, out = control(_heard(10.2, drive), state, _params(), OdometryPose(START))
    assert out.notes[0] == (logging.INFO, "found itself at (1.00, 3.00, 0.00) on its map")
    assert state.mode == "driving"


def test_a_robot_on_its_dock_does_not_step_aside() -> None:
    """At the end of a plan to its dock it stands whoever comes: stepping aside would take it
    off the charger (it did, and ran out beside the dock)."""
    through = Intent(
        10.0, path_intent(np.array([0.4, 3.0]), np.array([[3.0, 3.0]]), 0.3, 10.0, 2.0)
    )
    plan = replace(
        _plan(), task="dock-0", kind="dock", waypoints=np.array([START[:2]]), sweep_from=0
    )
    drive = Drive.of(plan, [], _params().follow)
    assert drive.follow is not None
    drive = replace(drive, follow=replace(drive.follow, index=1))
    _, out = _step(_heard(10.0, drive, {"robot-9": through}))
    assert (out.cmd_vel.v, out.cmd_vel.w) == (0.0, 0.0)
    assert out.status is not None and out.status.state == "done"


def test_a_plan_named_like_a_dock_trip_but_of_kind_clean_is_no_dock() -> None:
    """What a plan is for is its kind, not its name: at the end of a cleaning plan whose task
    happens to be called "dock-0" the robot is not on a charger and does step aside."""
    through = Intent(
        10.0, path_intent(np.array([0.4, 3.0]), np.array([[3.0, 3.0]]), 0.3, 10.0, 2.0)
    )
    plan = replace(_plan(), task="dock-0", waypoints=np.array([START[:2]]), sweep_from=0)
    drive = Drive.of(plan, [], _params().follow)
    assert drive.follow is not None and not drive.errand
    drive = replace(drive, follow=replace(drive.follow, index=1))
    _, out = _step(_heard(10.0, drive, {"robot-9": through}))
    assert (out.cmd_vel.v, out.cmd_vel.w) != (0.0, 0.0)
