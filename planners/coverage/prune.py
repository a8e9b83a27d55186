"""Dropping tasks whose floor other passes already clean.

:func:`prune_tasks` looks at the tasks alone (it runs before each fill-in round, whose tour
changes the transits anyway). :func:`prune_driven` runs on the final tours: under the repetition
metric every pass counts wherever it goes, so a transit over a lane piece,
a shoulder lane or a fill-in pass sweeps that floor as well as the task does. A task may go when
every cleanable cell its swath covers is covered by something else — the other kept tasks, or
the transits of the tour once the task is gone (the hop into it and out of it replaced by one
hop from the task before to the task after) — and that replacement hop is shorter than the two
hops and the task together. Tasks are tried longest first, so the most driving is saved first;
a task that must stay may still be cut back at either end by up to ``max(TRIMS)`` along its
path where the floor there is swept by something else (a lane running into a wall pass, a
fill-in pass along a lane, the next lane's turn), its hops moved with it.

Given a coverage floor (``min_cells``), :func:`prune_driven` then spends the cells covered
beyond it: the fill-in has cleaned a little more than the target at its cheapest, and a lane
piece that alone sweeps a few cells far off its neighbours costs more per cell than that. Drops
and cuts are made greedily by the fewest cells lost per metre saved, as long as the floor
holds — the budgeted form of greedy set-cover pruning. The greedy is lazy: it starts from the
figures the first pass found for the edits it could not make, and re-checks an edit's figures
when it comes up, since its neighbours may have changed. The transits its edits move sweep
floor anew (some of it floor nothing swept before, which adds to the budget), so the tasks under
them get one more lossless pass and the budget left one more greedy pass.
"""

from __future__ import annotations

import dataclasses
import heapq
import itertools
from collections.abc import Sequence

import numpy as np

from planners.coverage.metrics import capsule, to_cells
from planners.coverage.tasks import SweepTask
from planners.coverage.tour import path_of
from planners.coverage.transit import Transit
from planners.grid import GridMap
from planners.polyline import cut_start, path_length

Window = tuple[slice, slice]
Step = tuple[int, int]  # (robot, index in its tour)
Change = list[tuple[Window, np.ndarray, int]]  # footprints and how each changes the counts
# a task's path may lose this much (metres) at either end, and keeps at least MIN_PIECE
TRIMS = (0.1, 0.2, 0.3)
MIN_PIECE = 0.05


def footprint(grid: GridMap, path: np.ndarray, hw: float) -> tuple[Window, np.ndarray]:
    """The cells within the capsules of ``path`` (as ``metrics.swath`` covers them), as a
    window of the grid and the mask inside it."""
    pts = to_cells(grid, path)
    h = hw / grid.resolution
    lo = np.maximum(np.floor(pts.min(axis=0) - h).astype(int), 0)
    hi = np.minimum(np.ceil(pts.max(axis=0) + h).astype(int) + 1, grid.shape)
    shape = (max(int(hi[0] - lo[0]), 0), max(int(hi[1] - lo[1]), 0))
    mask = np.zeros(shape, dtype=bool)
    local = pts - lo
    for a, b in itertools.pairwise(local) if len(local) > 1 else [(local[0], local[0])]:
        at = capsule(a, b, h, shape)
        if at is not None:
            mask[at[0]] |= at[1]
    return (slice(int(lo[0]), int(hi[0])), slice(int(lo[1]), int(hi[1]))), mask


class Footprints:
    """The cleanable cells within the capsules of paths (:func:`footprint` masked by the
    cleanable floor), kept by each path's exact points: every fill-in round and the final
    pruning look at mostly the same task paths again. The masks are read-only."""

    def __init__(self, grid: GridMap, clean: np.ndarray, hw: float) -> None:
        self.grid, self.clean, self.hw = grid, clean, hw
        self._seen: dict[bytes, tuple[Window, np.ndarray]] = {}

    def __call__(self, path: np.ndarray) -> tuple[Window, np.ndarray]:
        key = np.ascontiguousarray(path, dtype=float).tobytes()
        if key not in self._seen:
            window, cells = footprint(self.grid, path, self.hw)
            cells &= self.clean[window]
            cells.flags.writeable = False
            self._seen[key] = (window, cells)
        return self._seen[key]


def prune_tasks(tasks, pieces, footprints: Footprints) -> list[list[tuple[int, int]]]:
    """The robots' tours without the tasks all of whose cleanable cells other kept tasks cover
    too (longest first): a pass whose floor later lanes sweep anyway, a lane piece that a
    shoulder lane and its neighbours already cover."""
    steps = [(r, k) for r, piece in enumerate(pieces) for k in range(len(piece))]
    paths = [path_of(tasks[t], o) for piece in pieces for t, o in piece]
    count = np.zeros(footprints.grid.shape, dtype=np.int32)
    own = []
    for path in paths:
        window, cells = footprints(path)
        count[window] += cells
        own.append((window, cells))
    length = [path_length(p) for p in paths]
    drop = set()
    for i in np.argsort(length)[::-1]:
        window, cells = own[i]
        if not (count[window][cells] < 2).any():
            count[window] -= cells
            drop.add(steps[i])
    return [[s for k, s in enumerate(p) if (r, k) not in drop] for r, p in enumerate(pieces)]


class _Hops:
    """Transits between points (planned once each by ``Transit.path``, which keeps them):
    their length, and their footprint when asked for."""

    def __init__(self, grid: GridMap, transit: Transit, clean: np.ndarray, hw: float) -> None:
        self.grid, self.transit, self.clean, self.hw = grid, transit, clean, hw
        self._lengths: dict[tuple[float, ...], float] = {}
        self._cells: dict[tuple[float, ...], tuple[Window, np.ndarray]] = {}

    def length(self, a: np.ndarray, b: np.ndarray) -> float:
        key = (*a.tolist(), *b.tolist())
        if key not in self._lengths:
            self._lengths[key] = path_length(self.transit.path(a, b))
        return self._lengths[key]

    def cells(self, a: np.ndarray, b: np.ndarray) -> tuple[Window, np.ndarray]:
        key = (*a.tolist(), *b.tolist())
        if key not in self._cells:
            window, cells = footprint(self.grid, self.transit.path(a, b), self.hw)
            self._cells[key] = (window, cells & self.clean[window])
        return self._cells[key]


def prune_driven(
    tasks: Sequence[SweepTask],
    pieces: Sequence[Sequence[tuple[int, int]]],
    start_xy: np.ndarray,
    footprints: Footprints,
    transit: Transit,
    min_cells: int | None = None,
) -> tuple[list[SweepTask], list[list[tuple[int, int]]]]:
    """The tasks and the robots' tours (``(task, option)`` per step, robot ``r`` starting at
    ``start_xy[r]``) without the tasks whose cleanable floor the rest of the driven path
    cleans too, transits included, and with paths shortened at an end where that loses no
    cell; then (with ``min_cells``) without the drops and cuts that save the most driving per
    cleanable cell lost while at least ``min_cells`` stay covered, and once more for what
    those edits made possible (see the module docstring). A shortened path is a new task,
    appended to the list. ``footprints`` gives the grid, the cleanable floor and the swath
    (and keeps the footprints of earlier prunings)."""
    tours = _Tours(tasks, pieces, start_xy, footprints, transit)
    lossy: list[tuple[float, int, int, int, float, int]] = []
    _lossless_pass(tours, list(tours.paths), lossy)
    if min_cells is None:
        return tours.result(tasks, pieces)
    tours.touched[:] = False
    _budget_pass(tours, lossy, min_cells)
    # the transits those edits moved sweep floor anew: the tasks under them may now go free,
    # and what that frees of the budget is spent too
    again = [s for s, (w, cells, _) in tours.own.items() if (tours.touched[w] & cells).any()]
    lossy = []
    _lossless_pass(tours, again, lossy)
    _budget_pass(tours, lossy, min_cells)
    return tours.result(tasks, pieces)


class _Tours:
    """The robots' driven tours as linked steps, and how often the tasks and transits sweep
    each cell."""

    def __init__(self, tasks, pieces, start_xy, footprints, transit) -> None:
        grid = footprints.grid
        self.grid, self.clean, self.start_xy = grid, footprints.clean, start_xy
        self.footprints = footprints
        self.hops = _Hops(grid, transit, footprints.clean, footprints.hw)
        self.count = np.zeros(grid.shape, dtype=np.int32)
        # cells the passes and transits of committed edits newly sweep
        self.touched = np.zeros(grid.shape, dtype=bool)
        self.paths: dict[Step, np.ndarray] = {}
        self.own: dict[Step, tuple[Window, np.ndarray, float]] = {}
        self.cut: set[Step] = set()
        for r, piece in enumerate(pieces):
            prev = start_xy[r]
            for k, (t, o) in enumerate(piece):
                path = path_of(tasks[t], o)
                self.paths[r, k] = path
                self.own[r, k] = self._footprint(path)
                hop_window, hop_cells = self.hops.cells(prev, path[0])
                self.count[self.own[r, k][0]] += self.own[r, k][1]
                self.count[hop_window] += hop_cells
                prev = path[-1]
        # kept steps as a doubly linked list per robot (-1: its start, len: its end)
        self.before = {s: s[1] - 1 for s in self.paths}
        self.after = {s: s[1] + 1 for s in self.paths}
        self.n_steps = [len(p) for p in pieces]

    def covered(self) -> int:
        return int(((self.count > 0) & self.clean).sum())

    def _footprint(self, path: np.ndarray) -> tuple[Window, np.ndarray, float]:
        return (*self.footprints(path), path_length(path))

    def edit(self, step: Step, end: int, cut: float) -> tuple[bool, np.ndarray | None]:
        """The step's path after an edit: None when dropped (``end`` −1), else ``cut`` metres
        shorter at its start (0) or end (1); False first when it is not that long."""
        if end < 0:
            return True, None
        path = self.paths[step]
        if path_length(path) < cut + MIN_PIECE:
            return False, None
        if end == 1:
            return True, cut_start(path[::-1], cut)[::-1]
        return True, cut_start(path, cut)

    def change(self, step: Step, path: np.ndarray | None) -> tuple[float, int, tuple]:
        """Driving saved, cleanable cells lost, and what :meth:`commit` needs, if ``step``
        were driven as ``path`` (None: dropped, the hops into and out of it become one).
        Footprints are only looked at when something is saved."""
        r = step[0]
        old_path = self.paths[step]
        window, cells, length = self.own[step]
        p, n = self.before[step], self.after[step]
        a = self.paths[r, p][-1] if p >= 0 else self.start_xy[r]
        nxt = self.paths[r, n][0] if n < self.n_steps[r] else None
        old = [(a, old_path[0])]
        if nxt is not None:
            old.append((old_path[-1], nxt))
        if path is None:
            new = [(a, nxt)] if nxt is not None else []
            new_length = 0.0
        else:
            new = [(a, path[0])]
            if nxt is not None:
                new.append((path[-1], nxt))
            new_length = path_length(path)
        hop = self.hops.length
        kept = length - new_length + sum(hop(*h) for h in old)
        # a transit is never shorter than the straight line: most edits fail that cheap test
        # before their new transits are planned
        if kept - sum(float(np.hypot(*(b - a))) for a, b in new) <= 1e-9:
            return 0.0, 0, ()
        saved = kept - sum(hop(*h) for h in new)
        if saved <= 1e-9:
            return saved, 0, ()
        changes: Change = [(window, cells, -1)]
        mine = None
        if path is not None:
            mine = self._footprint(path)
            changes.append((mine[0], mine[1], 1))
        changes += [(*self.hops.cells(*h), -1) for h in old]
        changes += [(*self.hops.cells(*h), 1) for h in new]
        return saved, self._lost(changes), (changes, mine)

    def _lost(self, changes: Change) -> int:
        """How many cleanable cells no pass would sweep any more after ``changes``."""
        r0 = min(w[0].start for w, _, _ in changes)
        c0 = min(w[1].start for w, _, _ in changes)
        r1 = max(w[0].stop for w, _, _ in changes)
        c1 = max(w[1].stop for w, _, _ in changes)
        delta = np.zeros((r1 - r0, c1 - c0), dtype=np.int32)
        for w, c, sign in changes:
            at = (slice(w[0].start - r0, w[0].stop - r0), slice(w[1].start - c0, w[1].stop - c0))
            delta[at] += sign * c
        count = self.count[r0:r1, c0:c1]
        return int(((count > 0) & (count + delta <= 0) & self.clean[r0:r1, c0:c1]).sum())

    def commit(self, step: Step, path: np.ndarray | None, change: tuple) -> None:
        changes, mine = change
        _apply(self.count, changes, 1)
        for w, c, sign in changes:
            if sign > 0:
                self.touched[w] |= c
        if path is not None:
            self.paths[step] = path
            self.own[step] = mine
            self.cut.add(step)
            return
        r, _ = step
        p, n = self.before.pop(step), self.after.pop(step)
        del self.paths[step], self.own[step]
        self.cut.discard(step)
        if p >= 0:
            self.after[r, p] = n
        if n < self.n_steps[r]:
            self.before[r, n] = p

    def result(self, tasks, pieces) -> tuple[list[SweepTask], list[list[tuple[int, int]]]]:
        out = list(tasks)
        kept = []
        for r, piece in enumerate(pieces):
            steps = []
            for k, (t, o) in enumerate(piece):
                if (r, k) not in self.paths:
                    continue
                if (r, k) in self.cut:
                    # its area and time taken in proportion to its length
                    share = self.own[r, k][2] / max(path_length(path_of(tasks[t], o)), 1e-9)
                    out.append(
                        dataclasses.replace(
                            tasks[t],
                            variants=(self.paths[r, k],),
                            area_m2=tasks[t].area_m2 * share,
                            time_s=tasks[t].time_s * share,
                        )
                    )
                    steps.append((len(out) - 1, 0))
                else:
                    steps.append((t, o))
            kept.append(steps)
        return out, kept


def _budget_pass(tours: _Tours, lossy: list, min_cells: int) -> None:
    """Make the edits of ``lossy`` (see :func:`_first_lossless`) that lose the fewest cells per
    metre saved, re-checking each as it comes up, while ``min_cells`` stay covered."""
    spare = tours.covered() - min_cells
    heap = [(rate, r, k, end, cut) for rate, r, k, end, cut, lost in lossy if lost <= spare]
    heapq.heapify(heap)
    while heap and spare > 0:
        _, r, k, end, cut = heapq.heappop(heap)
        if (r, k) not in tours.paths:
            continue
        ok, path = tours.edit((r, k), end, cut)
        if not ok:
            continue
        saved, lost, change = tours.change((r, k), path)
        if saved <= 1e-9 or lost > spare:
            continue
        if heap and lost / saved > heap[0][0] + 1e-12:
            heapq.heappush(heap, (lost / saved, r, k, end, cut))
            continue
        tours.commit((r, k), path, change)
        # a moved transit may also sweep floor nothing swept before
        spare = tours.covered() - min_cells


def _lossless_pass(tours: _Tours, steps: list[Step], lossy: list) -> None:
    """Drop each of ``steps`` (longest first), or else cut it back at either end, where that
    saves driving and loses no cell (see :func:`_first_lossless`)."""
    for step in sorted(steps, key=lambda s: -tours.own[s][2]):
        if step not in tours.paths or _first_lossless(tours, step, [(-1, 0.0)], lossy):
            continue
        for end in (0, 1):
            cuts = [(end, cut) for cut in sorted(TRIMS, reverse=True)]
            _first_lossless(tours, step, cuts, lossy)


def _first_lossless(tours: _Tours, step: Step, edits: list[tuple[int, float]], lossy: list) -> bool:
    """Make the first of ``edits`` (see :meth:`_Tours.edit`) that saves driving and loses
    no cell; whether there was one. The edits tried that save driving but lose cells go to
    ``lossy`` as (cells lost per metre saved, robot, step, end, cut, cells lost)."""
    for end, cut in edits:
        ok, path = tours.edit(step, end, cut)
        if not ok:
            continue
        saved, lost, change = tours.change(step, path)
        if saved <= 1e-9:
            continue
        if lost == 0:
            tours.commit(step, path, change)
            return True
        lossy.append((lost / saved, *step, end, cut, lost))
    return False


def _apply(count: np.ndarray, changes: Change, sign: int) -> None:
    for window, cells, s in changes:
        count[window] += sign * s * cells
