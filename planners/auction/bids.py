"""Commitments, bids and winner determination of sequential single-item auctions.

A robot's bid on a task is the marginal cost of appending it to what it has already won
(Koenig et al., "The power of sequential single-item auctions for agent coordination", AAAI
2006): the travel from the end of its commitments to the task's nearer end, plus the task's
time. The winner of a round is the bid that least increases the team objective (Lagoudakis et
al., "Auction-based multi-robot routing", RSS 2005), MiniMax: the makespan (the lowest total
time of the robot after it takes the task).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

Point = tuple[float, float]
# seconds from a point (2,) to each of K points (K, 2): (K,)
Travel = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Commitment:
    """What a robot has already won, in order.

    ``pose`` is where it is; ``current_s`` the remaining seconds of the task it is driving (0 if
    none) and ``current_end`` where that task ends (None if none); ``queued`` the won tasks not
    yet begun, each ``(entry, exit, time_s, travel_s)`` in the direction it will drive them, with
    ``travel_s`` the seconds from the previous end to its entry as priced when it was won (so
    the total needs no travel estimates again).
    """

    pose: Point
    current_s: float = 0.0
    current_end: Point | None = None
    queued: tuple[tuple[Point, Point, float, float], ...] = ()

    @property
    def end(self) -> Point:
        """Where the robot will be when all its commitments are done."""
        if self.queued:
            return self.queued[-1][1]
        return self.current_end if self.current_end is not None else self.pose

    @property
    def total_s(self) -> float:
        """Seconds until all its commitments are done."""
        return self.current_s + sum(t + travel for _, _, t, travel in self.queued)

    def with_task(
        self, entry: Point | np.ndarray, exit_: Point | np.ndarray, time_s: float, travel_s: float
    ) -> Commitment:
        """These commitments and then one more task, entered at ``entry``."""
        task = (_point(entry), _point(exit_), float(time_s), float(travel_s))
        return Commitment(self.pose, self.current_s, self.current_end, (*self.queued, task))

    def won(self, bid: Bid, entry: np.ndarray, exit_: np.ndarray, time_s: float) -> Commitment:
        """These commitments and then the task of ``bid`` (whose path runs ``entry`` → ``exit_``
        forwards), driven in the bid's direction after the bid's travel."""
        first, last = (exit_, entry) if bid.reverse else (entry, exit_)
        return self.with_task(first, last, time_s, bid.marginal_s - time_s)


@dataclass(frozen=True)
class Bid:
    """A robot's price for a task: ``marginal_s`` = travel from the end of its commitments to
    the task's nearer end + the task's time; ``total_s`` = its whole committed time with the
    task added (the makespan view); ``reverse``: drive the task's path backwards (enter at its
    exit)."""

    task: str
    robot: str
    marginal_s: float
    total_s: float
    reverse: bool


def make_bid(
    robot: str,
    task_id: str,
    entry: np.ndarray,
    exit_: np.ndarray,
    time_s: float,
    commitment: Commitment,
    travel: Travel,
    gain_s: float = 0.0,
) -> Bid:
    """The marginal cost of appending the task to ``commitment`` (Koenig et al. 2006 SSI bids):
    ``travel(from_xy, targets (2, 2))`` gives the seconds to the task's entry and exit; the bid
    takes the cheaper end (``reverse`` when that is the exit; the entry on a tie). ``gain_s``
    is what the task is worth beyond its work (a frontier's expected information, in seconds of
    travel: Burgard et al. 2005's utility against cost, U − β·V, as a cost) and is taken off."""
    ends = np.array([entry, exit_], dtype=float).reshape(2, 2)
    secs = np.asarray(travel(np.array(commitment.end, dtype=float), ends), dtype=float)
    reverse = bool(secs[1] < secs[0])
    marginal = float(secs[int(reverse)]) + float(time_s) - float(gain_s)
    return Bid(task_id, robot, marginal, commitment.total_s + marginal, reverse)


def winner(bids: Iterable[Bid]) -> Bid | None:
    """SSI winner determination over all (task, robot) bids of a round: the lowest
    ``total_s`` (Lagoudakis et al., RSS 2005, MiniMax team objective); ties broken by
    ``marginal_s``, then robot id, then task id. None for no bids."""
    return min(bids, key=lambda b: (b.total_s, b.marginal_s, b.robot, b.task), default=None)


def _point(xy: np.ndarray | Point) -> Point:
    x, y = np.asarray(xy, dtype=float).reshape(2)
    return float(x), float(y)
