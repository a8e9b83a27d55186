"""A plan's chain of tasks and its pieces, as both ends of ``coord/plan/<robot>`` read them.

A :class:`~fleet.protocol.Plan` drives a robot through the run of its queue that follows on
without a transit, its *chain*: ``chain`` names the tasks in order and ``chain_starts`` gives the
waypoint where each one's sweep begins; an empty chain means just ``task``, whose sweep begins at
``sweep_from``. The plan's segments from ``sweep_from`` on are its *pieces*, in the direction
driven: piece ``j`` runs from waypoint ``sweep_from + j`` to ``sweep_from + j + 1`` and is swept
once the robot has reached its far waypoint. The agent reports them (``RobotStatus.swept``); the
coordinator gives each task of the chain its slice of them. The coordinator cuts a plan short
under the same id when it takes back the end of a chain, and the robot drives on to the new end.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from fleet.protocol import Plan
from planners.auction import Task

# queued tasks whose ends meet within this go into one plan: the robot drives on between them
CHAIN_M = 0.01


def driven_ends(task: Task, reverse: bool) -> tuple[np.ndarray, np.ndarray]:
    """Where ``task``'s sweep begins and ends when driven as won (``reverse``: exit first)."""
    return (task.exit, task.entry) if reverse else (task.entry, task.exit)


def chain_length(drives: Sequence[tuple[Task, bool]]) -> int:
    """How many of the first ``drives`` ((task, reverse) in queue order) one plan chains: each
    begins within ``CHAIN_M`` of where the one before it ends."""
    if not drives:
        return 0
    n = 1
    while n < len(drives):
        end = driven_ends(*drives[n - 1])[1]
        if math.dist(end, driven_ends(*drives[n])[0]) > CHAIN_M:
            break
        n += 1
    return n


def chain_of(plan: Plan) -> list[str]:
    """The tasks ``plan`` drives, in order."""
    return list(plan.chain) or [plan.task]


def chain_starts(plan: Plan) -> np.ndarray:
    """The waypoint where each task of ``chain_of(plan)`` begins its sweep."""
    return plan.chain_starts if len(plan.chain) else np.array([plan.sweep_from])


def piece_count(waypoints: int, sweep_from: int) -> int:
    """How many pieces a plan of ``waypoints`` waypoints sweeps from ``sweep_from`` on."""
    return waypoints - 1 - sweep_from


def chain_pieces(plan: Plan) -> list[tuple[str, tuple[int, int]]]:
    """Each task of the plan with the slice of the plan's pieces that sweeps it."""
    starts = [int(s) - plan.sweep_from for s in chain_starts(plan)]
    ends = [*starts[1:], piece_count(len(plan.waypoints), plan.sweep_from)]
    return [(t, (a, b)) for t, a, b in zip(chain_of(plan), starts, ends, strict=True)]


def swept_pieces(
    waypoints: int, sweep_from: int, heading_for: int, missed: Sequence[int] = ()
) -> np.ndarray:
    """0/1 per piece of a plan of ``waypoints`` waypoints, for a robot heading for waypoint
    ``heading_for``: swept once it has reached the piece's far waypoint, unless that waypoint
    is one of ``missed`` (given up short of it)."""
    n = piece_count(waypoints, sweep_from)
    if n <= 0:
        return np.zeros(0, dtype=np.uint8)
    far = sweep_from + 1 + np.arange(n)
    return ((far < heading_for) & ~np.isin(far, np.asarray(missed, dtype=int))).astype(np.uint8)


def current_task(chain: Sequence[str], starts: np.ndarray, heading_for: int | None) -> str:
    """The task of a chain the robot is sweeping, heading for waypoint ``heading_for``: the last
    one whose sweep it has begun (the first while it drives the transit); "" without a chain or
    a path to follow (``heading_for`` None)."""
    if not chain or heading_for is None:
        return ""
    begun = int(np.searchsorted(starts, heading_for - 1, side="right"))
    return chain[min(max(begun - 1, 0), len(chain) - 1)]


def cut_plan(plan: Plan, j: int) -> Plan:
    """The plan up to the start of its ``j``-th chained task (same id: the robot drives on)."""
    end = int(plan.chain_starts[j])
    return Plan(
        plan.stamp,
        plan.plan_id,
        plan.task,
        plan.waypoints[: end + 1],
        plan.sweep_from,
        list(plan.chain[:j]),
        plan.chain_starts[:j],
        kind=plan.kind,
    )
