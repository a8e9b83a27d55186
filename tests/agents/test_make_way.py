"""The move out of a peer's way (:func:`agents.follow.escape.way_out`, ``make_way``): a robot
standing on the path of a robot it gives way to steps aside where there is room and backs out
of a passage one robot wide where there is none, ending out of the way; boxed in, it has none.
It does so only for a peer that says it is held up (``Intent.held_s``).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from agents.follow.escape import (
    IN_THE_WAY_M,
    blocks_the_way,
    in_their_way,
    make_way,
    way_out,
)
from agents.follow.motion import follow_step
from agents.follow.state import FollowParams, FollowState, Situation
from agents.peers import held_for, held_up_near, path_intent
from fleet.params import load_fleet_config
from fleet.protocol import Intent

CFG = load_fleet_config()
PARAMS = FollowParams.of(CFG)
R = CFG.robot.radius
NONE = np.zeros((0, 2))


def _line(x0: float, x1: float, y: float, n: int = 200) -> np.ndarray:
    return np.column_stack([np.linspace(x0, x1, n), np.full(n, y)])


def _end(pose: tuple[float, float, float], move: tuple[float, float]) -> np.ndarray:
    heading, distance = move
    return np.array(pose[:2]) + distance * np.array([math.cos(heading), math.sin(heading)])


def _clearance(point: np.ndarray, centres: np.ndarray) -> float:
    return float(np.hypot(*(centres - point).T).min()) - R


def test_in_the_open_a_robot_on_a_peers_path_steps_aside_rather_than_back() -> None:
    # the peer at the origin heads +x; its intent covers a metre; the robot stands on it at 0.7
    tube = _line(0.0, 1.0, 0.0, 11)
    pose = (0.7, 0.0, math.pi)
    assert in_their_way(Situation(pose, (0.0, 0.0), NONE, tube, (tube,)), R)
    # a peer that drives on is not held up: nobody is in its way
    assert not in_their_way(Situation(pose, (0.0, 0.0), NONE, tube), R)
    move = way_out(pose, NONE, tube, R)
    assert move is not None
    heading, distance = move
    assert abs(math.cos(heading)) < 0.35  # across the peer's path
    assert distance <= 0.5
    assert _clearance(_end(pose, move), tube) >= R + IN_THE_WAY_M


def test_in_a_passage_one_robot_wide_the_robot_backs_out_the_way_the_peer_heads() -> None:
    # walls 0.65 m apart from x = -2 to x = 1 (a table beside a wall), open room beyond x = 1;
    # the peer comes along the middle from the left, its intent up to x = 0.3; the robot faces it
    walls = np.vstack([_line(-2.0, 1.0, 0.325), _line(-2.0, 1.0, -0.325)])
    tube = _line(-0.4, 0.3, 0.0, 8)
    pose = (0.55, 0.0, math.pi)
    move = way_out(pose, walls, tube, R)
    assert move is not None
    heading, _ = move
    assert math.cos(heading) > 0.9
    end = _end(pose, move)
    assert _clearance(end, tube) >= R + IN_THE_WAY_M
    along = np.array(pose[:2]) + np.linspace(0, move[1], 20)[:, None] * (end - pose[:2]) / move[1]
    assert np.hypot(*(along[:, None, :] - walls[None]).transpose(2, 0, 1)).min() >= R


def test_boxed_in_on_a_peers_path_there_is_no_way_out() -> None:
    ring = np.array([[0.2 * math.cos(a), 0.2 * math.sin(a)] for a in np.linspace(0, 6.28, 90)])
    assert way_out((0.0, 0.0, 0.0), ring, _line(-1.0, 1.0, 0.0, 21), R) is None


def test_make_way_starts_a_move_in_the_cheaper_sense_and_out_of_the_way() -> None:
    tube = _line(0.0, 1.0, 0.0, 11)
    # facing across the path (+y): the move aside is driven forward or in reverse, never turned
    state = make_way(
        FollowState(np.array([[0.7, 0.0], [-1.0, 0.0]]), index=1, blocked_s=1.0),
        Situation((0.7, 0.0, math.pi / 2), (0.0, 0.0), NONE, tube, (tube,)),
        PARAMS,
    )
    assert state.escape_m > 0 and state.blocked_s == 0.0 and state.making_way
    assert abs(math.remainder(state.escape_heading - math.pi / 2, 2 * math.pi)) < 0.2
    end = np.array([0.7, 0.0]) + state.escape_sign * state.escape_m * np.array(
        [math.cos(state.escape_heading), math.sin(state.escape_heading)]
    )
    assert _clearance(end, tube) >= R + IN_THE_WAY_M


def test_at_the_blind_end_of_a_passage_no_move_gets_out_of_the_way() -> None:
    # the passage above, closed at x = 0.9: the robot can back up, but not out of the peer's way
    walls = np.vstack(
        [_line(-2.0, 0.9, 0.325), _line(-2.0, 0.9, -0.325), [[0.9, y] for y in (-0.2, 0, 0.2)]]
    )
    assert way_out((0.55, 0.0, math.pi), walls, _line(-0.4, 0.3, 0.0, 8), R) is None


def _steps(held: tuple[np.ndarray, ...], seconds: float) -> FollowState:
    """A robot at work on the path of a peer coming along +x, facing its own next waypoint
    beyond the peer, stepped ``seconds`` by the follower with the peer ``held`` up or not."""
    tube = _line(0.0, 1.0, 0.0, 11)
    state = FollowState(np.array([[0.7, 0.0], [-1.0, 0.0]]), index=1)
    now = Situation((0.7, 0.0, math.pi), (0.0, 0.0), NONE, tube, held)
    for _ in range(round(seconds / PARAMS.dt)):
        state, _ = follow_step(state, now, PARAMS)
    return state


def test_a_robot_at_work_makes_way_only_for_a_peer_that_says_it_is_held_up() -> None:
    seconds = CFG.agent.make_way_after_s + 2 * PARAMS.dt
    assert _steps((_line(0.0, 1.0, 0.0, 11),), seconds).making_way
    # the same peer driving on: the robot waits for it (its body is in the scan, not here)
    assert not _steps((), seconds).making_way


def test_a_robot_announces_how_long_it_has_come_no_closer_to_its_waypoint() -> None:
    follow = FollowState(np.array([[0.0, 0.0], [1.0, 0.0]]), index=1, stalled_s=1.2, yielded_s=0.8)
    # waiting for a peer is not being held up by one that gives way
    assert held_for(follow) == pytest.approx(1.2)
    assert held_for(None) == 0.0
    assert held_for(FollowState(np.array([[0.0, 0.0]]), index=1)) == 0.0  # done


def test_only_peers_held_up_long_enough_near_the_robot_count_as_held() -> None:
    points = path_intent(np.array([0.0, 0.0]), np.array([[1.0, 0.0]]), 0.3, 10.0, 2.0)
    up = np.array([0.0, 0.0, 1.0])
    intents = {
        "robot-0": Intent(10.0, points, 1, 1, held_s=1.5),
        "robot-1": Intent(10.0, points + 0.9 * up, 1, 1, held_s=0.4),
        "robot-2": Intent(10.0, points + 2.5 * up, 1, 1, held_s=5.0),
    }
    # robot-3 at (0, 0.5): robot-0 and robot-1 are within reach (0.64 m), robot-2 is not
    held = held_up_near(intents, 10.0, 0.5, np.array([0.0, 0.5]), 1.0, 2 * R + 0.3)
    assert len(held) == 1 and np.allclose(held[0], points[:, 1:])


def test_a_peer_is_blocked_in_a_passage_one_robot_wide_and_goes_round_in_a_room() -> None:
    # the peer comes along y = 0 from x = -0.6 toward x = 1.0; the robot stands at the origin
    tube = _line(-0.6, 1.0, 0.0, 17)
    passage = np.vstack([_line(-1.5, 1.5, 0.325, 300), _line(-1.5, 1.5, -0.325, 300)])
    assert blocks_the_way((0.0, 0.0, 0.0), passage, tube, R)
    assert not blocks_the_way((0.0, 0.0, 0.0), NONE, tube, R)
    # a passage wide enough for both: the peer passes beside the robot standing at one wall
    wide = np.vstack([_line(-1.5, 1.5, 0.6, 300), _line(-1.5, 1.5, -0.6, 300)])
    assert not blocks_the_way((0.0, 0.38, 0.0), wide, tube + np.array([0.0, -0.2]), R)
    # in the open, a robot standing where the peer's path ends is in its way all the same
    assert blocks_the_way((0.9, 0.0, 0.0), NONE, _line(0.0, 1.0, 0.0, 11), R)


def test_in_a_room_a_held_peer_is_left_to_go_round() -> None:
    tube = _line(-0.6, 1.0, 0.0, 17)
    passage = np.vstack([_line(-1.5, 1.5, 0.325, 300), _line(-1.5, 1.5, -0.325, 300)])
    peer_at = tube[:1]
    narrow = Situation((0.0, 0.0, 0.0), (0.0, 0.0), passage, tube, (tube,), peer_at)
    assert in_their_way(narrow, R)
    assert not in_their_way(replace(narrow, obstacles=NONE), R)


def test_a_robot_that_made_way_does_not_escape_back_into_a_held_peers_way() -> None:
    # out of the way beside the peer's path (0.5 m off it), its own path runs through it: DWA
    # stops it short of the peer's discs, and the escape toward its path would take it back in
    tube = _line(0.0, 1.0, 0.0, 11)
    state = FollowState(np.array([[0.5, 0.5], [0.5, -1.0]]), index=1)
    seconds = CFG.agent.escape_after_s + 2 * PARAMS.dt
    for held in ((tube,), ()):
        now = Situation((0.5, 0.5, -math.pi / 2), (0.0, 0.0), NONE, tube, held)
        after = state
        for _ in range(round(seconds / PARAMS.dt)):
            after, _ = follow_step(after, now, PARAMS)
        assert (after.escape_m > 0) is (not held)
