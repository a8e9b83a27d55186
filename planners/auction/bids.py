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


@dataclass(frozen=True, eq=False)
class Prices:
    """One robot's prices for K tasks at once (:func:`make_bids`), each as in :class:`Bid`:
    ``marginal_s`` (K,), ``total_s`` (K,), ``reverse`` (K,) bool."""

    marginal_s: np.ndarray
    total_s: np.ndarray
    reverse: np.ndarray


def make_bids(
    entries: np.ndarray,
    exits: np.ndarray,
    times_s: np.ndarray,
    commitment: Commitment,
    travel: Travel,
    gains_s: np.ndarray | None = None,
) -> Prices:
    """The marginal cost of appending each of K tasks to ``commitment`` (Koenig et al. 2006
    SSI bids), all in one ``travel`` call from the commitment's end to the tasks' 2K ends: each
    bid takes the cheaper end (``reverse`` when that is the task's exit; the entry on a tie).
    ``gains_s`` (K,) is what each task is worth beyond its work (a frontier's expected
    information, in seconds of travel: Burgard et al. 2005's utility against cost, U − β·V, as
    a cost), taken off its bid."""
    entries = np.asarray(entries, dtype=float).reshape(-1, 2)
    exits = np.asarray(exits, dtype=float).reshape(-1, 2)
    k = len(entries)
    ends = np.concatenate([entries, exits])
    secs = np.asarray(travel(np.array(commitment.end, dtype=float), ends), dtype=float)
    to_entry, to_exit = secs[:k], secs[k:]
    reverse = to_exit < to_entry
    gains = np.zeros(k) if gains_s is None else np.asarray(gains_s, dtype=float)
    marginal = np.where(reverse, to_exit, to_entry) + np.asarray(times_s, dtype=float) - gains
    return Prices(marginal, commitment.total_s + marginal, reverse)


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
    """One task's bid (:func:`make_bids` of one)."""
    p = make_bids(entry, exit_, np.array([time_s]), commitment, travel, np.array([gain_s]))
    return Bid(task_id, robot, float(p.marginal_s[0]), float(p.total_s[0]), bool(p.reverse[0]))


def ranked(
    total_s: np.ndarray, marginal_s: np.ndarray, robots: np.ndarray, tasks: np.ndarray
) -> np.ndarray:
    """The order in which bids win, best first, by SSI winner determination (Lagoudakis et al.,
    RSS 2005, MiniMax team objective): the lowest ``total_s``; ties broken by ``marginal_s``,
    then robot id, then task id (all (N,); indices into them)."""
    return np.lexsort((tasks, robots, marginal_s, total_s))


def winner(bids: Iterable[Bid]) -> Bid | None:
    """The best of ``bids`` by :func:`ranked`; None for no bids."""
    bids = list(bids)
    if not bids:
        return None
    order = ranked(
        np.array([b.total_s for b in bids]),
        np.array([b.marginal_s for b in bids]),
        np.array([b.robot for b in bids]),
        np.array([b.task for b in bids]),
    )
    return bids[int(order[0])]


def _point(xy: np.ndarray | Point) -> Point:
    x, y = np.asarray(xy, dtype=float).reshape(2)
    return float(x), float(y)
