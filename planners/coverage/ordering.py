"""The split of one tour among k robots (the order itself: :mod:`planners.coverage.tour`)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment

from planners.coverage.tasks import SweepTask


def split_tour(
    tour: Sequence[SweepTask], starts: np.ndarray, speed: float
) -> list[list[SweepTask]]:
    """Cut the single-robot tour into ``len(starts)`` contiguous pieces minimizing the makespan.

    A piece costs the straight-line time from the nearest start to its first task, its tasks'
    times and the straight-line times between them; a dynamic program over cut points finds the
    cuts minimizing the largest piece, and the Hungarian method (scipy linear_sum_assignment)
    gives each robot the piece nearest its start. Each robot's set stays contiguous along the
    tour, so it is mostly one connected stretch of the floor.
    """
    k = len(starts)
    n = len(tour)
    if n == 0:
        return [[] for _ in range(k)]
    first = np.array([t.variants[0][0] for t in tour])
    last = np.array([t.variants[0][-1] for t in tour])
    work = np.array([t.time_s for t in tour])
    hop = np.zeros(n)
    hop[1:] = np.hypot(*(first[1:] - last[:-1]).T) / speed
    prefix = np.concatenate([[0.0], np.cumsum(work + hop)])
    approach = np.min(
        np.hypot(*(first[:, None, :] - starts[None, :, :]).transpose(2, 0, 1)), axis=1
    )
    approach = approach / speed
    # cost[i, j]: piece of tasks i..j-1 (j > i)
    i_idx = np.arange(n)[:, None]
    j_idx = np.arange(n + 1)[None, :]
    cost = prefix[j_idx] - prefix[i_idx] - hop[i_idx] + approach[i_idx]
    cost = np.where(j_idx > i_idx, cost, math.inf)
    best = np.full((k + 1, n + 1), math.inf)
    cut = np.zeros((k + 1, n + 1), dtype=int)
    best[0, 0] = 0.0
    for m in range(1, k + 1):
        for j in range(0, n + 1):
            cand = np.maximum(best[m - 1, :j], cost[:j, j]) if j else np.array([])
            options = np.append(cand, best[m - 1, j])  # an empty piece
            c = int(np.argmin(options))
            best[m, j] = options[c]
            cut[m, j] = c if c < j else j
    bounds = [n]
    for m in range(k, 0, -1):
        bounds.append(cut[m, bounds[-1]])
    bounds = bounds[::-1]
    pieces = [list(tour[bounds[m] : bounds[m + 1]]) for m in range(k)]
    travel = np.zeros((k, k))
    for r in range(k):
        for m, piece in enumerate(pieces):
            if piece:
                ends = (piece[0].variants[0][0], piece[-1].variants[0][-1])
                travel[r, m] = min(float(np.hypot(*(e - starts[r]))) for e in ends)
    rows, cols = linear_sum_assignment(travel)
    return [pieces[c] for _, c in sorted(zip(rows, cols, strict=True))]
