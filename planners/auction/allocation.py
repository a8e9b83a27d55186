"""Offline sequential single-item auctions: every round at once in one process.

The coordinator runs the same rounds over the bus, one task call and its bids at a time; this is
the reference it can be compared with, and what benchmarks use to weigh it against a static
split of the tour.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from planners.auction.bids import Bid, Commitment, Travel, make_bids, ranked
from planners.auction.tasks import Task

Allocation = dict[str, list[tuple[str, bool]]]


def allocate(
    tasks: Sequence[Task],
    robots: Mapping[str, Commitment],
    travel: Travel,
) -> Allocation:
    """Sequential single-item auctions (Koenig et al. 2006): repeat {every robot bids on every
    unallocated task; the MiniMax winner (:func:`planners.auction.bids.ranked`) takes it; only
    the winner's commitment changes} until all are allocated. Returns robot →
    [(task id, reverse)] in allocation order, every robot of ``robots`` present.

    Only the winner's bids change from one round to the next, so only they are priced again
    (:func:`planners.auction.bids.make_bids`, all its tasks in one travel call).
    """
    out: Allocation = {r: [] for r in robots}
    if len({t.id for t in tasks}) != len(tasks):
        raise ValueError("task ids must be unique")
    if not tasks or not robots:
        return out
    entries = np.array([t.entry for t in tasks], dtype=float)
    exits = np.array([t.exit for t in tasks], dtype=float)
    times = np.array([t.time_s for t in tasks], dtype=float)
    names = list(robots)
    held = dict(robots)
    prices = {r: make_bids(entries, exits, times, held[r], travel) for r in names}
    # every (robot, task) pair, robot-major
    robot_of = np.repeat(np.array(names), len(tasks))
    task_of = np.tile(np.array([t.id for t in tasks]), len(names))
    open_ = np.ones(len(tasks), dtype=bool)
    while open_.any():
        live = np.flatnonzero(np.tile(open_, len(names)))
        total = np.concatenate([prices[r].total_s for r in names])[live]
        marginal = np.concatenate([prices[r].marginal_s for r in names])[live]
        best = int(live[ranked(total, marginal, robot_of[live], task_of[live])[0]])
        robot, i = names[best // len(tasks)], best % len(tasks)
        p = prices[robot]
        bid = Bid(
            tasks[i].id, robot, float(p.marginal_s[i]), float(p.total_s[i]), bool(p.reverse[i])
        )
        out[robot].append((bid.task, bid.reverse))
        held[robot] = held[robot].won(bid, tasks[i].entry, tasks[i].exit, tasks[i].time_s)
        open_[i] = False
        prices[robot] = make_bids(entries, exits, times, held[robot], travel)
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
