"""Boustrophedon cellular decomposition (Choset 2000) of a grid mask, swept row by row.

A slice (one row of the mask) falls into runs of free cells. Sweeping from the first row to the
last, a run continues the cell of the run below when exactly one run of each row touches the
other; where the number of touching runs changes (an obstacle starts or ends: Choset's critical
points) cells end and new ones begin. Every row of a cell is therefore one interval, which a
boustrophedon path sweeps with lanes along the rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components


@dataclass(frozen=True, eq=False)
class MonotoneCell:
    """Rows ``row0 .. row0 + len(left) - 1``; row ``row0 + k`` spans ``left[k] .. right[k]``."""

    row0: int
    left: np.ndarray
    right: np.ndarray

    @property
    def rows(self) -> int:
        return len(self.left)

    @property
    def cells(self) -> int:
        return int((self.right - self.left + 1).sum())


def row_runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(row, first col, last col) of every run of True cells, sorted by row then column."""
    padded = np.pad(mask.astype(np.int8), ((0, 0), (1, 1)))
    d = np.diff(padded, axis=1)
    r_start, c_start = np.nonzero(d == 1)
    _r_end, c_end = np.nonzero(d == -1)
    return r_start, c_start, c_end - 1


def decompose(mask: np.ndarray, max_step: int = 6) -> tuple[np.ndarray, list[MonotoneCell]]:
    """Label image (0 outside, 1..n) and the cells of the boustrophedon decomposition."""
    row, c0, c1 = row_runs(mask)
    n = len(row)
    labels = np.zeros(mask.shape, dtype=np.int32)
    if n == 0:
        return labels, []
    width = mask.shape[1] + 2
    key_start = row * width + c0
    key_end = row * width + c1
    # runs of the next row that touch run a: start <= a.c1 and end >= a.c0 (4-connectivity)
    lo = np.searchsorted(key_end, (row + 1) * width + c0, side="left")
    hi = np.searchsorted(key_start, (row + 1) * width + c1, side="right")
    up = np.maximum(hi - lo, 0)
    down = np.zeros(n, dtype=np.int64)
    single = up == 1
    src = np.repeat(np.arange(n), up)
    dst = lo[src] + _ranks(up)
    np.add.at(down, dst, 1)
    keep = single[src] & (down[dst] == 1)
    graph = coo_matrix((np.ones(int(keep.sum())), (src[keep], dst[keep])), shape=(n, n))
    _, comp = connected_components(graph, directed=False)
    order = np.lexsort((row, comp))
    bounds = np.flatnonzero(np.diff(comp[order])) + 1
    cells = [
        MonotoneCell(int(row[ids[0]]), c0[ids].copy(), c1[ids].copy())
        for ids in np.split(order, bounds)
    ]
    group = _merge_stacked(cells, max_step)
    merged: list[MonotoneCell] = []
    new_id = np.zeros(len(cells), dtype=np.int32)
    for g in sorted(set(group), key=group.index):
        members = sorted(
            (k for k in range(len(cells)) if group[k] == g), key=lambda k: cells[k].row0
        )
        new_id[members] = len(merged) + 1
        merged.append(
            MonotoneCell(
                cells[members[0]].row0,
                np.concatenate([cells[k].left for k in members]),
                np.concatenate([cells[k].right for k in members]),
            )
        )
    lengths = c1 - c0 + 1
    rr = np.repeat(row, lengths)
    cc = np.repeat(c0, lengths) + _ranks(lengths)
    labels[rr, cc] = np.repeat(new_id[comp], lengths)
    return labels, merged


def _merge_stacked(cells: list[MonotoneCell], max_step: int) -> list[int]:
    """Group cells into vertical chains: a cell and the cell right above it merge when each is
    the other's widest touching neighbour and their sides shift by at most ``max_step`` cells
    where they meet (the coverage planner allows any step: its clamp lanes and fill-in passes sweep
    the rim of a shoulder). A chain is still one
    interval per row, so it is swept like one cell with fewer transits (the merging step of
    most BCD implementations)."""
    tops: dict[int, list[int]] = {}
    for k, c in enumerate(cells):
        tops.setdefault(c.row0 + c.rows - 1, []).append(k)
    above: dict[int, tuple[int, int]] = {}
    below: dict[int, tuple[int, int]] = {}
    for b, cb in enumerate(cells):
        for a in tops.get(cb.row0 - 1, []):
            ca = cells[a]
            overlap = min(ca.right[-1], cb.right[0]) - max(ca.left[-1], cb.left[0]) + 1
            step = max(abs(ca.left[-1] - cb.left[0]), abs(ca.right[-1] - cb.right[0]))
            if overlap <= 0 or step > max_step:
                continue
            if overlap > above.get(a, (-1, 0))[1]:
                above[a] = (b, overlap)
            if overlap > below.get(b, (-1, 0))[1]:
                below[b] = (a, overlap)
    group = list(range(len(cells)))
    for a, (b, _) in sorted(above.items()):
        if below.get(b, (-1, 0))[0] == a:
            old, new = group[b], group[a]
            group = [new if g == old else g for g in group]
    return group


def _ranks(counts: np.ndarray) -> np.ndarray:
    """0, 1, .., counts[0]-1, 0, 1, .., counts[1]-1, ... (positions within repeated groups)."""
    return np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
