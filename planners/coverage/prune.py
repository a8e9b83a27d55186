"""Dropping tasks whose floor other passes already clean.

:func:`prune_tasks` looks at the tasks alone (it runs before each fill-in round, whose tour
changes the transits anyway). :func:`prune_driven` runs on the final tours: under the repetition
metric every pass counts wherever it goes, so a transit over a lane piece,
a shoulder lane or a fill-in pass sweeps that floor as well as the task does. A task may go when
every cleanable cell its swath covers is covered by something else — the other kept tasks, or
the transits of the tour once the task is gone (the hop into it and out of it replaced by one
hop from the task before to the task after) — and that replacement hop is shorter than the two
hops and the task together. Tasks are tried longest first, so the most driving is saved first.
"""

from __future__ import annotations

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
) -> list[list[tuple[int, int]]]:
    """The robots' tours (``(task, option)`` per step, robot ``r`` starting at
    ``start_xy[r]``) without the tasks whose cleanable floor the rest of its driven path
    cleans too, transits included (see the module docstring)."""
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
    for r, k in sorted(own, key=lambda s: -own[s][2]):
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
        if sum(h[0] for h in new) >= length + sum(h[0] for h in old) - 1e-9:
            continue
        changes = [(window, cells, -1)]
        changes += [(w, c, -1) for _, w, c in old] + [(w, c, 1) for _, w, c in new]
        was = [count[w] > 0 for w, _, _ in changes]
        _apply(count, changes, 1)
        lost = (clean[w] & c & (count[w] == 0) for (w, _, _), c in zip(changes, was, strict=True))
        if any(m.any() for m in lost):
            _apply(count, changes, -1)
            continue
        drop.add((r, k))
        if p >= 0:
            after[r, p] = n
        if n < len(legs):
            before[r, n] = p
    return [[s for k, s in enumerate(p) if (r, k) not in drop] for r, p in enumerate(pieces)]


def _apply(count: np.ndarray, changes: list[tuple[Window, np.ndarray, int]], sign: int) -> None:
    for window, cells, s in changes:
        count[window] += sign * s * cells
