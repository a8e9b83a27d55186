"""Offline sequential single-item auctions: every round at once in one process.

The coordinator runs the same rounds over the bus, one task call and its bids at a time; this is
the reference it can be compared with, and what benchmarks use to weigh it against a static
split of the tour.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from planners.auction.bids import Bid, Commitment, Travel, make_bid, winner
from planners.auction.tasks import Task

Allocation = dict[str, list[tuple[str, bool]]]


def allocate(
    tasks: Sequence[Task],
    robots: Mapping[str, Commitment],
    travel: Travel,
) -> Allocation:
    """Sequential single-item auctions (Koenig et al. 2006): repeat {every robot bids on every
    unallocated task; the MiniMax winner (:func:`planners.auction.bids.winner`) takes
    it; only the winner's commitment changes} until all are allocated. Returns robot →
    [(task id, reverse)] in allocation order, every robot of ``robots`` present.

    Only the winner's bids change from one round to the next, so only they are priced again.
    """
    out: Allocation = {r: [] for r in robots}
    by_id = {t.id: t for t in tasks}
    if len(by_id) != len(tasks):
        raise ValueError("task ids must be unique")
    held = dict(robots)
    bids: dict[tuple[str, str], Bid] = {
        (r, t.id): _bid(r, t, held[r], travel) for r in held for t in tasks
    }
    while (best := winner(bids.values())) is not None:
        task = by_id.pop(best.task)
        out[best.robot].append((best.task, best.reverse))
        held[best.robot] = held[best.robot].won(best, task.entry, task.exit, task.time_s)
        bids = {k: b for k, b in bids.items() if b.task != best.task}
        for t in by_id.values():
            bids[best.robot, t.id] = _bid(best.robot, t, held[best.robot], travel)
    return out


def makespan(
    allocation: Mapping[str, Sequence[tuple[str, bool]]],
    tasks: Sequence[Task],
    robots: Mapping[str, Commitment],
    travel: Travel,
) -> float:
    """Seconds until the slowest robot is done: its commitments, then its allocated tasks in
    order, each driven in the given direction after the travel from the previous end (0 with
    no robots)."""
    by_id = {t.id: t for t in tasks}
    worst = 0.0
    for robot, start in robots.items():
        held = start
        for task_id, reverse in allocation.get(robot, ()):
            task = by_id[task_id]
            first, last = (task.exit, task.entry) if reverse else (task.entry, task.exit)
            hop = float(travel(np.array(held.end, dtype=float), first[None, :])[0])
            held = held.with_task(first, last, task.time_s, hop)
        worst = max(worst, held.total_s)
    return worst


def _bid(robot: str, task: Task, held: Commitment, travel: Travel) -> Bid:
    return make_bid(robot, task.id, task.entry, task.exit, task.time_s, held, travel)
