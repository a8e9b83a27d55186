"""Dropping tasks whose floor other passes already clean.

:func:`prune_tasks` looks at the tasks alone (it runs before each fill-in round, whose tour
changes the transits anyway). :func:`prune_driven` runs on the final tours: under the repetition
metric every pass counts wherever it goes, so a transit over a lane piece,
a shoulder lane or a fill-in pass sweeps that floor as well as the task does. A task may go when
every cleanable cell its swath covers is covered by something else — the other kept tasks, or
the transits of the tour once the task is gone (the hop into it and out of it replaced by one
hop from the task before to the task after) — and that replacement hop is shorter than the two
hops and the task together. Tasks are tried longest first, so the most driving is saved first.

Given a coverage floor (``min_cells``), :func:`prune_driven` then spends the cells covered
beyond it: the fill-in has cleaned a little more than the target at its cheapest, and a lane
piece that alone sweeps a few cells far off its neighbours costs more per cell than that. Tasks
go greedily by the fewest cells lost per metre saved (lazy greedy: a task's figures are
re-checked when it comes up, since its neighbours may have gone), as long as the floor holds —
the budgeted form of greedy set-cover pruning.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Sequence

import numpy as np

from planners.coverage.metrics import swath
from planners.coverage.tasks import SweepTask
from planners.coverage.tour import path_of
from planners.coverage.transit import Transit
from planners.grid import GridMap

Window = tuple[slice, slice]


def footprint(grid: GridMap, path: np.ndarray, hw: float) -> tuple[Window, np.ndarray]:
    """The cells within the capsules of ``path`` (``metrics.swath``), as a window of the grid
    and the mask inside it."""
    rc = grid.world_to_cell(path)
    pad = math.ceil(hw / grid.resolution) + 1
    r0, c0 = np.maximum(rc.min(axis=0) - pad, 0)
    r1, c1 = np.minimum(rc.max(axis=0) + pad + 1, grid.shape)
    origin = (grid.origin[0] + c0 * grid.resolution, grid.origin[1] + r0 * grid.resolution)
    shape = (int(r1 - r0), int(c1 - c0))
    window = GridMap(np.zeros(shape, bool), np.zeros(shape, bool), grid.resolution, origin)
    return (slice(int(r0), int(r1)), slice(int(c0), int(c1))), swath(window, path, hw)[0]


def prune_tasks(grid, tasks, pieces, clean, hw) -> list[list[tuple[int, int]]]:
    """The robots' tours without the tasks all of whose cleanable cells other kept tasks cover
    too (longest first): a pass whose floor later lanes sweep anyway, a lane piece that a
    shoulder lane and its neighbours already cover."""
    steps = [(r, k) for r, piece in enumerate(pieces) for k in range(len(piece))]
    paths = [path_of(tasks[t], o) for piece in pieces for t, o in piece]
    count = np.zeros(grid.shape, dtype=np.int32)
    own = []
    for path in paths:
        window, cells = footprint(grid, path, hw)
        cells &= clean[window]
        count[window] += cells
        own.append((window, cells))
    length = [float(np.hypot(*np.diff(p, axis=0).T).sum()) for p in paths]
    drop = set()
    for i in np.argsort(length)[::-1]:
        window, cells = own[i]
        if not (count[window][cells] < 2).any():
            count[window] -= cells
            drop.add(steps[i])
    return [[s for k, s in enumerate(p) if (r, k) not in drop] for r, p in enumerate(pieces)]


class _Hops:
    """Transits between points, with their length and footprint, planned once each."""

    def __init__(self, grid: GridMap, transit: Transit, clean: np.ndarray, hw: float) -> None:
        self.grid, self.transit, self.clean, self.hw = grid, transit, clean, hw
        self._kept: dict[tuple[float, ...], tuple[float, Window, np.ndarray]] = {}

    def __call__(self, a: np.ndarray, b: np.ndarray) -> tuple[float, Window, np.ndarray]:
        key = (*a.tolist(), *b.tolist())
        if key not in self._kept:
            path = self.transit.path(a, b)
            window, cells = footprint(self.grid, path, self.hw)
            length = float(np.hypot(*np.diff(path, axis=0).T).sum())
            self._kept[key] = (length, window, cells & self.clean[window])
        return self._kept[key]


def prune_driven(
    grid: GridMap,
    tasks: Sequence[SweepTask],
    pieces: Sequence[Sequence[tuple[int, int]]],
    start_xy: np.ndarray,
    clean: np.ndarray,
    hw: float,
    transit: Transit,
    min_cells: int | None = None,
) -> list[list[tuple[int, int]]]:
    """The robots' tours (``(task, option)`` per step, robot ``r`` starting at
    ``start_xy[r]``) without the tasks whose cleanable floor the rest of its driven path
    cleans too, transits included, and then (with ``min_cells``) without the tasks that save
    the most driving per cleanable cell lost while at least ``min_cells`` stay covered (see
    the module docstring)."""
    hops = _Hops(grid, transit, clean, hw)
    count = np.zeros(grid.shape, dtype=np.int32)
    paths = [[path_of(tasks[t], o) for t, o in piece] for piece in pieces]
    own = {}
    for r, legs in enumerate(paths):
        prev = start_xy[r]
        for k, path in enumerate(legs):
            window, cells = footprint(grid, path, hw)
            cells &= clean[window]
            own[r, k] = (window, cells, float(np.hypot(*np.diff(path, axis=0).T).sum()))
            _, hop_window, hop_cells = hops(prev, path[0])
            count[window] += cells
            count[hop_window] += hop_cells
            prev = path[-1]
    # the kept steps of each tour as a doubly linked list (-1: the start, len: the end)
    before = {s: s[1] - 1 for s in own}
    after = {s: s[1] + 1 for s in own}
    drop: set[tuple[int, int]] = set()

    def removal(r: int, k: int) -> tuple[float, int, list[tuple[Window, np.ndarray, int]]]:
        """Driving saved, cleanable cells lost and the count changes if step k of robot r
        went (the hops into and out of it replaced by one)."""
        legs = paths[r]
        path = legs[k]
        window, cells, length = own[r, k]
        p, n = before[r, k], after[r, k]
        a = legs[p][-1] if p >= 0 else start_xy[r]
        old = [hops(a, path[0])]
        new = []
        if n < len(legs):
            old.append(hops(path[-1], legs[n][0]))
            new.append(hops(a, legs[n][0]))
        saved = length + sum(h[0] for h in old) - sum(h[0] for h in new)
        changes = [(window, cells, -1)]
        changes += [(w, c, -1) for _, w, c in old] + [(w, c, 1) for _, w, c in new]
        if saved <= 1e-9:
            return saved, 0, changes
        _apply(count, changes, 1)
        r0 = min(w[0].start for w, _, _ in changes)
        c0 = min(w[1].start for w, _, _ in changes)
        r1 = max(w[0].stop for w, _, _ in changes)
        c1 = max(w[1].stop for w, _, _ in changes)
        lost = np.zeros((r1 - r0, c1 - c0), dtype=bool)
        for w, c, _ in changes:
            rows, cols = (
                slice(w[0].start - r0, w[0].stop - r0),
                slice(w[1].start - c0, w[1].stop - c0),
            )
            lost[rows, cols] |= clean[w] & c & (count[w] == 0)
        _apply(count, changes, -1)
        return saved, int(lost.sum()), changes

    def remove(r: int, k: int, changes: list[tuple[Window, np.ndarray, int]]) -> None:
        _apply(count, changes, 1)
        drop.add((r, k))
        p, n = before[r, k], after[r, k]
        if p >= 0:
            after[r, p] = n
        if n < len(paths[r]):
            before[r, n] = p

    for r, k in sorted(own, key=lambda s: -own[s][2]):
        saved, lost, changes = removal(r, k)
        if saved > 1e-9 and lost == 0:
            remove(r, k, changes)
    if min_cells is not None:
        spare = int(((count > 0) & clean).sum()) - min_cells
        heap = []
        for r, k in own:
            if (r, k) not in drop:
                saved, lost, _ = removal(r, k)
                if saved > 1e-9 and lost <= spare:
                    heapq.heappush(heap, (lost / saved, r, k))
        while heap and spare > 0:
            _, r, k = heapq.heappop(heap)
            saved, lost, changes = removal(r, k)
            if saved <= 1e-9 or lost > spare:
                continue
            if heap and lost / saved > heap[0][0] + 1e-12:
                heapq.heappush(heap, (lost / saved, r, k))
                continue
            remove(r, k, changes)
            spare -= lost
    return [[s for k, s in enumerate(p) if (r, k) not in drop] for r, p in enumerate(pieces)]


def _apply(count: np.ndarray, changes: list[tuple[Window, np.ndarray, int]], sign: int) -> None:
    for window, cells, s in changes:
        count[window] += sign * s * cells
