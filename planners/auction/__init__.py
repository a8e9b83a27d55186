"""The market's pure core: tasks, their pieces and remainders, bids and winner determination.

The model:

* **Tasks.** One coverage tour of the whole floor (``planners.coverage.plan_coverage`` with one
  robot) is cut at its vertices into consecutive tasks of about ``target_s`` seconds of
  estimated driving, preferably at the transits between sweeps (:func:`split_tour`; the cut
  rule is in :mod:`planners.auction.tasks`). A task is a path with its area, time and the
  boustrophedon cells (Choset 2000) it sweeps.
* **Pieces and remainders.** A task's N − 1 segments are its pieces. A robot reports which it
  has swept; the :func:`remainder` of a task is the path through its unswept pieces, and is
  what goes back to the market when the robot is lost (ids "t07" → "t07.1" → "t07.2").
* **Bids.** Sequential single-item (SSI) auctions (Koenig et al., "The power of sequential
  single-item auctions for agent coordination", AAAI 2006): a robot bids on a task the
  marginal cost of appending it to its :class:`Commitment` — the travel from where its won
  work ends to the task's nearer end (a task may be driven backwards) plus the task's time
  (:func:`make_bid`; a round's tasks all in one go, :func:`make_bids`). Travel is priced on
  the robot's own map (:func:`travel_times`, :class:`TravelGrid`: Dijkstra on a coarsened
  grid).
* **Winner determination.** Each round every robot bids on every open task and one (task,
  robot) pair wins (:func:`winner`); only the winner's commitment changes. The team objective
  is MiniMax (Lagoudakis et al., "Auction-based multi-robot routing", RSS 2005): the lowest
  total committed time of the robot after the award (least makespan: what a cleaning job is
  judged by), in the order :func:`ranked` gives. :func:`allocate` runs all rounds in one
  process; :func:`makespan` judges the result.
* **Lots.** A call sells a :class:`Lot`: one task, or — in the first allocation — a region of
  consecutive tasks, one per robot (:func:`regions`), so each robot starts on a contiguous part
  of the floor.

Public API::

    Task(id, path, area_m2, time_s, cells)            .entry .exit .pieces
    split_tour(path, cell_labels, grid, target_s, params, robot, prefix="t") -> tuple[Task, ...]
    remainder(task, swept, new_id, params, robot) -> Task | None
    ahead_of(task, xy, reverse, clearance, new_id, params, robot) -> Task | None
    travel_times(free, resolution, origin, start_xy, targets_xy, speed) -> (K,) seconds
    TravelGrid(free, resolution, origin, speed)(start_xy, targets_xy) -> (K,) seconds
    floor_travel(floor, radius, speed) -> TravelGrid on the floor plan, obstacles grown
    Commitment(pose, current_s=0.0, current_end=None, queued=())
        .end .total_s .with_task(entry, exit_, time_s, travel_s) .won(bid, entry, exit_, time_s)
    Bid(task, robot, marginal_s, total_s, reverse)
    make_bids(entries, exits, times_s, commitment, travel, gains_s=None) -> Prices
    make_bid(robot, task_id, entry, exit_, time_s, commitment, travel) -> Bid
    ranked(total_s, marginal_s, robots, tasks) -> indices, best first; winner(bids) -> Bid | None
    allocate(tasks, robots, travel) -> {robot: [(task id, reverse)]}
    makespan(allocation, tasks, robots, travel) -> seconds
    Lot(id, tasks, entry, exit, time_s, area_m2, gain_s=0).driven(back)
    task_lot(task); regions(tasks, k) -> lots
"""

from planners.auction.allocation import allocate, makespan
from planners.auction.bids import (
    Bid,
    Commitment,
    Prices,
    Travel,
    make_bid,
    make_bids,
    ranked,
    winner,
)
from planners.auction.lots import Lot, regions, task_lot
from planners.auction.tasks import Task, ahead_of, remainder, split_tour
from planners.auction.travel import UNREACHABLE_FACTOR, TravelGrid, floor_travel, travel_times

__all__ = [
    "UNREACHABLE_FACTOR",
    "Bid",
    "Commitment",
    "Lot",
    "Prices",
    "Task",
    "Travel",
    "TravelGrid",
    "ahead_of",
    "allocate",
    "floor_travel",
    "make_bid",
    "make_bids",
    "makespan",
    "ranked",
    "regions",
    "remainder",
    "split_tour",
    "task_lot",
    "travel_times",
    "winner",
]
