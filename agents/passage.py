"""A robot's side of a transit planned in space and time: keep the order of passage.

The coordinator plans transits through the cells of a transit graph and sends each with the
action dependencies of the plan (Hönig et al., RA-L 2019; ``planners.dependencies``): the robot
heads for waypoint ``at`` only once the peer has reached its waypoint ``passed``. Peers say how
far they are in their intents (plan id and the waypoint they head for). Exact times are not
kept: a late robot only makes the ones after it in a cell wait, never meet it there.

A dependency is met when the peer heads for a waypoint past ``passed`` of that plan, drives a
newer plan (it is done with that transit), dropped the plan, or has been silent for
``silent_s`` (a dead robot's body stays where it stopped; the DWA and the intents deal with
it). A peer not heard from yet, or still on an older plan (the round's plan has not reached
it), is waited for. Holding one waypoint for longer than the agent's ``hold_max_s`` is given
up, so a lost message never stops a robot for good (:func:`hold`). A robot that will have to
hold before its next waypoint brakes to rest on the one before it (:func:`hold`'s stop): that
point is its cell's, clear of the cell it waits to enter.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from agents.follow.motion import advance
from agents.follow.state import FollowState
from agents.peers import PeerProgress
from fleet.params import AgentParams
from fleet.protocol import Plan
from planners.dependencies import Dependency, blocking


@dataclass(frozen=True, eq=False)
class Waits:
    """A plan's dependencies, one row per (waypoint, peer)."""

    at: np.ndarray
    peer: tuple[str, ...]
    plan: np.ndarray
    passed: np.ndarray

    @classmethod
    def of(cls, plan: Plan) -> Waits:
        n = len(plan.wait_at)
        if not (len(plan.wait_for) == len(plan.wait_plan) == len(plan.wait_passed) == n):
            raise ValueError(f"plan {plan.plan_id}: its wait_* fields differ in length")
        return cls(
            np.asarray(plan.wait_at, dtype=np.int64),
            tuple(plan.wait_for),
            np.asarray(plan.wait_plan, dtype=np.int64),
            np.asarray(plan.wait_passed, dtype=np.int64),
        )

    @classmethod
    def none(cls) -> Waits:
        empty = np.zeros(0, dtype=np.int64)
        return cls(empty, (), empty, empty)


def waiting_for(
    waits: Waits,
    index: int,
    peers: Mapping[str, PeerProgress],
    now: float,
    silent_s: float,
) -> list[str]:
    """The peers a robot heading for its waypoint ``index`` must still wait for: the
    dependencies still blocking (``planners.dependencies.blocking``) given how far each peer
    is along the plan the dependency names."""
    reached: dict[str, float] = {}
    for name, plan in zip(waits.peer, waits.plan.tolist(), strict=True):
        p = peers.get(name)
        if p is None:
            continue
        if now - p.stamp > silent_s or p.plan_id > plan or (p.plan_id == plan and p.waypoint < 0):
            reached[name] = math.inf
        elif p.plan_id == plan:
            reached[name] = p.waypoint - 1
    edges = [
        Dependency(int(at), name, int(passed))
        for at, name, passed in zip(waits.at, waits.peer, waits.passed, strict=True)
    ]
    return sorted({d.peer for d in blocking(edges, index, reached)})


@dataclass(frozen=True)
class Holding:
    """Where the robot holds for its peers, (plan, waypoint, since when in sim s), None while
    it does not; and the (plan, waypoint) pairs it gave up holding at."""

    at: tuple[int, int, float] | None = None
    given_up: frozenset[tuple[int, int]] = frozenset()


def hold(
    holding: Holding,
    follow: FollowState,
    xy: np.ndarray,
    plan_id: int,
    waits: Waits,
    peers: Mapping[str, PeerProgress],
    now: float,
    agent: AgentParams,
) -> tuple[Holding, FollowState | None, int, tuple[tuple[int, str], ...]]:
    """Whether a robot at ``xy`` on plan ``plan_id`` must hold for a peer before the waypoint it
    heads for: the follower advanced to where the robot stands if it must, None if it may drive
    on; the waypoint it must come to rest on when it may drive on but would be held before the
    one after (``FollowState.stop_at``, else -1); and the log lines (level, text after the
    robot's id) of holding and of giving up.

    Told to hold only once it had reached the waypoint before, a robot at full speed came to
    rest its braking distance (0.25 m) past it, inside the next cell, where its body stood in
    the way of the peer it waited for. Holding before one waypoint for longer than
    ``agent.hold_max_s`` is given up, and that waypoint of that plan is never held at again."""
    if not len(waits.at):
        return holding, None, -1, ()
    ahead = advance(follow, xy, agent)
    key = (plan_id, ahead.index)
    if ahead.done or key in holding.given_up:
        return holding, None, -1, ()
    names = waiting_for(waits, ahead.index, peers, now, agent.hold_silent_s)
    if not names:
        nxt = ahead.index + 1
        held_next = (
            nxt < len(ahead.waypoints)
            and (plan_id, nxt) not in holding.given_up
            and waiting_for(waits, nxt, peers, now, agent.hold_silent_s)
        )
        return Holding(None, holding.given_up), None, ahead.index if held_next else -1, ()
    who = ", ".join(names)
    if holding.at is None or holding.at[:2] != key:
        note = (logging.INFO, f"holds before waypoint {ahead.index} for {who}")
        return Holding((*key, now), holding.given_up), ahead, -1, (note,)
    if now - holding.at[2] > agent.hold_max_s:
        note = (
            logging.WARNING,
            f"gave up holding before waypoint {ahead.index} after {agent.hold_max_s:.0f} s: "
            f"{who} not heard to pass",
        )
        return Holding(None, holding.given_up | {key}), None, -1, (note,)
    return holding, ahead, -1, ()
