"""A robot's side of the order of passage: which peers it still waits for."""

from __future__ import annotations

import numpy as np
import pytest

from agents.passage import Waits, waiting_for
from agents.peers import PeerProgress
from fleet.protocol import Plan


def _waits() -> Waits:
    plan = Plan(
        0.0,
        7,
        "t01",
        np.zeros((6, 2)),
        5,
        wait_at=np.array([2, 2, 4], dtype=np.int32),
        wait_for=["robot-1", "robot-2", "robot-1"],
        wait_plan=np.array([8, 9, 8], dtype=np.int32),
        wait_passed=np.array([3, 1, 5], dtype=np.int32),
    )
    return Waits.of(plan)


def test_a_peer_is_waited_for_until_it_heads_past_the_waypoint_it_must_pass() -> None:
    w = _waits()
    at = {"robot-1": PeerProgress(8, 3, 10.0), "robot-2": PeerProgress(9, 2, 10.0)}
    assert waiting_for(w, 2, at, 10.0, 2.0) == ["robot-1"]
    at["robot-1"] = PeerProgress(8, 4, 10.1)
    assert waiting_for(w, 2, at, 10.1, 2.0) == []
    # other waypoints have their own peers; a waypoint without any waits for no one
    assert waiting_for(w, 4, at, 10.1, 2.0) == ["robot-1"]
    assert waiting_for(w, 3, at, 10.1, 2.0) == []


def test_unheard_older_newer_dropped_and_silent_peers() -> None:
    w = _waits()
    # not heard from yet, or still on an older plan: the round's plan has not reached it
    assert waiting_for(w, 2, {}, 0.0, 2.0) == ["robot-1", "robot-2"]
    older = {"robot-1": PeerProgress(5, 40, 1.0), "robot-2": PeerProgress(6, 40, 1.0)}
    assert waiting_for(w, 2, older, 1.0, 2.0) == ["robot-1", "robot-2"]
    # a newer plan, a dropped plan (-1), or silence: no longer in the way of the order
    done = {"robot-1": PeerProgress(12, 0, 1.0), "robot-2": PeerProgress(9, -1, 1.0)}
    assert waiting_for(w, 2, done, 1.0, 2.0) == []
    assert waiting_for(w, 2, older, 3.5, 2.0) == []


def test_wait_fields_of_unequal_length_are_refused() -> None:
    bad = Plan(0.0, 1, "t", np.zeros((2, 2)), 1, wait_at=np.array([1], dtype=np.int32))
    with pytest.raises(ValueError, match="differ in length"):
        Waits.of(bad)
