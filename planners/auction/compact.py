"""Compact regions: the tasks split into one connected group per robot, near it, balanced by time.

The objective is DARP's (Kapoutsis et al., "DARP: Divide Areas Algorithm for Optimal Multi-Robot
Coverage Path Planning", J. Intell. Robot. Syst. 2017): every robot gets one connected region
that contains its own start, and the regions' workloads are equal. DARP reaches it by iterative
re-weighting of a distance assignment on a grid; robots that start side by side at a dock have
nearly equal distances to every cell, which that re-weighting cannot tell apart. Here the same
objective is reached on the tasks' adjacency graph (two tasks are adjacent when their paths come
within ``adjacent_m`` of each other) the way graph partitioners do it: greedy graph growing
(Karypis & Kumar, "A fast and high quality multilevel scheme for partitioning irregular graphs",
SIAM J. Sci. Comput. 1998, GGGP), then boundary refinement in the manner of Fiduccia–Mattheyses
(1982), but on the makespan instead of the cut:

1. **Growing, one robot after another** (the one farthest from any task first). A robot's seed
   is the task nearest it (travel to its nearer end), unless a robot still to come is nearer
   to that task; then its nearest task that is no other robot's nearest. Its group then takes,
   again and again, a task bordering it, together with whatever that task's taking cuts off
   from the tasks not taken, while the group ends nearer its share of the work left (estimated
   time: travel from its start to its seed, and its tasks' times) with it than without:
   preferably a task that is no robot's nearest, then one that cuts nothing off, then the one
   nearest the seed. It leaves a task for each robot still to come. The last robot takes the
   rest.
2. **Repair.** A piece of a group cut off from its seed goes to a neighbouring group, one whose
   seed it reaches if there is one (DARP's connectivity step).
3. **Driving order.** Each group is ordered from its robot's start by the coverage planner's own
   tour heuristic (:func:`planners.coverage.tour.plan_tour`: greedy, 2-opt with reversal, Or-opt,
   each task forwards or backwards), on the travel times between task ends; a group's time is
   that tour's: travel from the start, the tasks' times and the travel between them.
4. **Refinement.** While a task on a group's border can move to a neighbouring group, with
   whatever of its group only it joins to the group's seed (never the seed itself), so that
   the longer time of the two goes down, a move is made: out of the slowest group that can
   give one, the one that lowers that time most (priced with the tasks cut out of one tour and
   put into the other one by one where each adds least). The two groups are then ordered again
   from there. Moves between any two neighbours, not only out of the slowest, let a group
   hemmed in at the dock take work over from its neighbours while they take over from theirs.

Times come from one ``travel(from_xy, targets_xy)`` callable, the market's own
(:class:`planners.auction.TravelGrid`), so a region is priced as its bids will price it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from planners.auction.bids import Travel
from planners.auction.tasks import Task
from planners.coverage.tour import TaskEnds, plan_tour, tour_cost
from planners.polyline import densify

# the refinement makes at most this many moves per task (a bound; it stops far sooner)
_MOVES_PER_TASK = 4
_EPS = 1e-6


@dataclass(frozen=True)
class Region:
    """One robot's group: ``robot`` the index of its start, ``tasks`` in driving order,
    ``reverse`` whether each is driven backwards, ``time_s`` the estimated time from the start
    (travel to the first, the tasks, the travel between them), ``start_s`` the first of these,
    ``seed`` the task it grew from."""

    robot: int
    tasks: tuple[str, ...]
    reverse: tuple[bool, ...]
    time_s: float
    start_s: float
    seed: str


def compact_regions(
    tasks: Sequence[Task], starts: np.ndarray, travel: Travel, adjacent_m: float
) -> tuple[Region, ...]:
    """Partition ``tasks`` into one connected, compact group per start of ``starts`` ((k, 2)
    world metres), balanced by estimated time (the steps: module docstring). A start gets an
    empty region when there are fewer tasks than starts. Deterministic for equal input."""
    pts = np.asarray(starts, dtype=float).reshape(-1, 2)
    k, n = len(pts), len(tasks)
    if k < 1:
        raise ValueError("need at least one start")
    if not adjacent_m > 0:
        raise ValueError(f"adjacent_m must be > 0, got {adjacent_m}")
    if n == 0:
        return tuple(Region(r, (), (), 0.0, 0.0, "") for r in range(k))
    ends = _task_ends(tasks, pts, travel)
    reach = np.minimum(ends.cost[2 * n :, 0 : 2 * n : 2], ends.cost[2 * n :, 1 : 2 * n : 2])
    adjacent = adjacency(tasks, adjacent_m)
    c = ends.cost[: 2 * n, : 2 * n].reshape(n, 2, n, 2)
    between = np.minimum(c.min(axis=(1, 3)), c.min(axis=(1, 3)).T)
    owner, seeds = _peel(reach, between, adjacent, np.array([t.time_s for t in tasks]))
    tours = {r: plan_tour(_members(owner, r), 2 * n + r, ends) for r in range(k)}
    _refine(owner, tours, seeds, adjacent, ends)
    return tuple(
        Region(
            r,
            tuple(tasks[t].id for t, _ in tours[r]),
            tuple(bool(o) for _, o in tours[r]),
            _time(tours[r], 2 * n + r, ends),
            float(ends.cost[2 * n + r, 2 * tours[r][0][0] + tours[r][0][1]]) if tours[r] else 0.0,
            tasks[seeds[r]].id if seeds[r] >= 0 else "",
        )
        for r in range(k)
    )


def adjacency(tasks: Sequence[Task], adjacent_m: float) -> np.ndarray:
    """(n, n) bool: whether the paths of two tasks come within ``adjacent_m`` of each other
    (sampled every ``adjacent_m / 2``; a task is not adjacent to itself)."""
    n = len(tasks)
    pts = [densify(np.asarray(t.path, dtype=float), adjacent_m / 2) for t in tasks]
    label = np.concatenate([np.full(len(p), i) for i, p in enumerate(pts)])
    tree = cKDTree(np.vstack(pts))
    out = np.zeros((n, n), dtype=bool)
    for i, p in enumerate(pts):
        near = tree.query_ball_point(p, adjacent_m)
        out[i, np.unique(label[np.concatenate([np.asarray(x, dtype=int) for x in near])])] = True
    np.fill_diagonal(out, False)
    return out | out.T


def pieces(adjacent: np.ndarray) -> np.ndarray:
    """The connected piece of each node of a small graph ((n, n) bool), numbered from 0 in
    the order of each piece's first node (breadth-first search)."""
    n = len(adjacent)
    label = np.full(n, -1)
    count = 0
    for first in range(n):
        if label[first] >= 0:
            continue
        label[first] = count
        front = np.zeros(n, dtype=bool)
        front[first] = True
        while front.any():
            front = adjacent[front].any(axis=0) & (label < 0)
            label[front] = count
        count += 1
    return label


def _task_ends(tasks: Sequence[Task], starts: np.ndarray, travel: Travel) -> TaskEnds:
    """The tour planner's view of the tasks: option 0 drives a task forwards (entry point
    ``2t``, exit ``2t + 1``), option 1 backwards; costs are travel seconds between all ends and
    from the starts (points ``2n ..``), a task's length its time."""
    n = len(tasks)
    pts = np.vstack([np.array([[*t.entry], [*t.exit]]) for t in tasks] + [starts])
    cost = np.vstack([np.asarray(travel(p, pts), dtype=float) for p in pts])
    return TaskEnds(
        offset=2 * np.arange(n, dtype=np.int64),
        count=np.full(n, 2, dtype=np.int64),
        entry=np.arange(2 * n, dtype=np.int64),
        exit=np.arange(2 * n, dtype=np.int64) ^ 1,
        length=np.repeat([float(t.time_s) for t in tasks], 2),
        cost=np.pad(cost, ((0, 0), (0, 1))),
    )


def _peel(
    reach: np.ndarray, between: np.ndarray, adjacent: np.ndarray, times: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(each task's group, each group's seed; −1 for none): the groups grown one after another,
    each to its share of the work left, the last taking the rest (the steps: module docstring).
    """
    k, n = reach.shape
    owner, seeds = np.full(n, -1), np.full(k, -1)
    robots = [int(r) for r in np.argsort(-reach.min(axis=1), kind="stable")]
    # each robot's nearest task, kept from the groups grown before its own while they can do
    # without it
    reserved = {r: int(np.argmin(reach[r])) for r in robots}
    for i, r in enumerate(robots):
        free = owner < 0
        if not free.any():
            break
        seeds[r] = _seed(r, free, reach, reserved, len(robots) - i - 1)
        reserved.pop(r, None)
        if i == len(robots) - 1:
            owner[free] = r
            break
        if seeds[r] < 0:
            continue
        owner[seeds[r]] = r
        load = reach[r, seeds[r]] + times[owner == r].sum()
        share = (times[owner < 0].sum() + load + sum(reach[q].min() for q in robots[i + 1 :])) / (
            len(robots) - i
        )
        while (
            take := _next(
                r,
                owner,
                between[seeds[r]],
                adjacent,
                times,
                share - load,
                reserved,
                len(robots) - i - 1,
            )
        ) is not None:
            owner[take] = r
            load += times[take].sum()
            reserved = {q: m for q, m in reserved.items() if owner[m] < 0}
    _repair(owner, seeds, adjacent)
    return owner, seeds


def _repair(owner: np.ndarray, seeds: np.ndarray, adjacent: np.ndarray) -> None:
    """Give every piece of a group cut off from its seed to a neighbouring group, one whose
    seed's piece it borders if there is one (in place; DARP's connectivity repair)."""
    for _ in range(len(owner)):
        moved = False
        for g in np.unique(owner):
            members = _members(owner, int(g))
            main = set(_joined(int(seeds[g]), members, adjacent)) if seeds[g] >= 0 else set()
            stray = [m for m in members if m not in main]
            if not stray or not main:
                continue
            piece = _joined(stray[0], stray, adjacent)
            touching = np.flatnonzero(adjacent[piece].any(axis=0) & (owner != g))
            if not len(touching):
                continue
            rooted = [
                j
                for j in touching
                if j in _joined(int(seeds[owner[j]]), _members(owner, int(owner[j])), adjacent)
            ]
            owner[piece] = owner[(rooted or list(touching))[0]]
            moved = True
        if not moved:
            return


def _joined(t: int, members: list[int], adjacent: np.ndarray) -> list[int]:
    """The members ``t`` is joined to through members (``t`` among them)."""
    rest = [t, *(m for m in members if m != t)]
    label = pieces(adjacent[np.ix_(rest, rest)])
    return [m for m, lab in zip(rest, label, strict=True) if lab == label[0]]


def _seed(r: int, free: np.ndarray, reach: np.ndarray, reserved: dict[int, int], later: int) -> int:
    """The task robot ``r`` grows from: its nearest, unless taken or reserved for a robot
    nearer to it; else its nearest task neither taken nor reserved; else, while more tasks are
    left than the ``later`` robots still to come, its nearest not taken; else −1 (none)."""
    keep = reserved.get(r, -1)
    rivals = [q for q, t in reserved.items() if t == keep and q != r]
    if keep >= 0 and free[keep] and all(reach[q, keep] > reach[r, keep] for q in rivals):
        return keep
    others = np.isin(np.arange(len(free)), [t for q, t in reserved.items() if q != r])
    open_ = free & ~others
    if not open_.any():
        if free.sum() <= later:
            return -1
        open_ = free
    return int(np.argmin(np.where(open_, reach[r], np.inf)))


def _cut_off(owner: np.ndarray, adjacent: np.ndarray, times: np.ndarray) -> np.ndarray:
    """The tasks not taken that lie apart from the biggest piece (by time) of those not taken."""
    rest = np.flatnonzero(owner < 0)
    if not len(rest):
        return rest
    label = pieces(adjacent[np.ix_(rest, rest)])
    main = np.argmax(np.bincount(label, weights=times[rest] + _EPS))
    return rest[label != main]


def _next(
    r: int,
    owner: np.ndarray,
    near: np.ndarray,
    adjacent: np.ndarray,
    times: np.ndarray,
    room: float,
    reserved: dict[int, int],
    later: int,
) -> np.ndarray | None:
    """What group ``r`` takes next (None for nothing): a task bordering it, with the tasks its
    taking cuts off from the rest, whose time fits in ``room`` seconds (half of it may
    overflow: the group ends nearer its share with it than without) and that leaves a task
    for each of the ``later`` robots still to come. Preferred: one reserved
    for no other robot, then one that cuts nothing off, then the nearest to the group's seed
    (``near``: travel from it to each task)."""
    frontier = np.flatnonzero((owner < 0) & adjacent[owner == r].any(axis=0))
    best: tuple[tuple[bool, bool, float], np.ndarray] | None = None
    for t in frontier:
        trial = owner.copy()
        trial[t] = r
        take = np.concatenate([[t], _cut_off(trial, adjacent, times)])
        if times[take].sum() / 2 > room or (owner < 0).sum() - len(take) < later:
            continue
        key = (bool(set(take.tolist()) & set(reserved.values())), len(take) > 1, float(near[t]))
        if best is None or key < best[0]:
            best = (key, take)
    return None if best is None else best[1]


def _members(owner: np.ndarray, r: int) -> list[int]:
    return [int(t) for t in np.flatnonzero(owner == r)]


def _refine(
    owner: np.ndarray,
    tours: dict[int, list[tuple[int, int]]],
    seeds: np.ndarray,
    adjacent: np.ndarray,
    ends: TaskEnds,
) -> None:
    """Move border tasks between adjacent groups while a move lowers the longer time of the
    two (in place). Each move lowers the groups' times sorted from the longest down, so it
    ends; the bound on moves only guards against float noise."""
    n = len(owner)
    times = {r: _time(tours[r], 2 * n + r, ends) for r in tours}
    for _ in range(_MOVES_PER_TASK * n):
        move = _best_move(owner, tours, times, seeds, adjacent, ends)
        if move is None:
            return
        bundle, g, h, kept, grown = move
        owner[bundle] = h
        tours[g] = plan_tour([m for m, _ in kept], 2 * n + g, ends, kept) if kept else []
        tours[h] = plan_tour([m for m, _ in grown], 2 * n + h, ends, grown)
        times[g], times[h] = _time(tours[g], 2 * n + g, ends), _time(tours[h], 2 * n + h, ends)


Tour = list[tuple[int, int]]


def _best_move(
    owner: np.ndarray,
    tours: dict[int, Tour],
    times: dict[int, float],
    seeds: np.ndarray,
    adjacent: np.ndarray,
    ends: TaskEnds,
) -> tuple[list[int], int, int, Tour, Tour] | None:
    """(tasks moved, from, to, the giving tour after, the taking tour after) of the move out of
    the slowest group that can give one, lowering the pair's longer time most; None if no move
    lowers it. A move takes a border task and whatever of its group that task alone joins to
    the group's seed. Priced without reordering: the tasks cut out of one tour, and put into
    the other's one by one where each adds least."""
    n = len(owner)
    best: tuple[tuple[float, float], tuple[list[int], int, int, Tour, Tour]] | None = None
    for g, tour in tours.items():
        for t, _ in tour:
            if t == seeds[g]:
                continue
            bundle = _hanging_on(t, [m for m, _ in tour], int(seeds[g]), adjacent)
            kept = [(m, o) for m, o in tour if m not in bundle]
            after_g = _time(kept, 2 * n + g, ends)
            for h in sorted({int(owner[j]) for j in np.flatnonzero(adjacent[t])} - {g}):
                grown = list(tours[h])
                for m in bundle:
                    _, (p, o) = _insertion(grown, m, 2 * n + h, ends)
                    grown.insert(p, (m, o))
                drop = times[g] - max(after_g, _time(grown, 2 * n + h, ends))
                key = (times[g], drop)
                if drop > _EPS and (best is None or key > best[0]):
                    best = (key, (bundle, g, h, kept, grown))
    return None if best is None else best[1]


def _hanging_on(t: int, members: list[int], seed: int, adjacent: np.ndarray) -> list[int]:
    """``t`` and the members of its group that lose their way to the group's ``seed`` without
    it."""
    rest = [m for m in members if m != t]
    label = pieces(adjacent[np.ix_(rest, rest)])
    home = label[rest.index(seed)]
    return [t, *(m for m, lab in zip(rest, label, strict=True) if lab != home)]


def _time(tour: Sequence[tuple[int, int]], start: int, ends: TaskEnds) -> float:
    return tour_cost(tour, start, ends) if tour else 0.0


def _insertion(
    tour: Sequence[tuple[int, int]], t: int, start: int, ends: TaskEnds
) -> tuple[float, tuple[int, int]]:
    """What putting task ``t`` into ``tour`` adds where it adds least, and there (position,
    option)."""
    c, seq = ends.cost, np.array([ends.offset[m] + o for m, o in tour], dtype=np.int64)
    src = np.concatenate([[start], ends.exit[seq]]).astype(np.int64)
    dst = ends.entry[seq]
    opts = ends.offset[t] + np.arange(ends.count[t])
    into = c[src[:, None], ends.entry[opts][None, :]] + ends.length[opts][None, :]
    out = np.zeros_like(into)
    out[:-1] = c[ends.exit[opts][None, :], dst[:, None]] - c[src[:-1], dst][:, None]
    added = into + out
    p, o = np.unravel_index(int(np.argmin(added)), added.shape)
    return float(added[p, o]), (int(p), int(o))
