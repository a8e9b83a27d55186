"""The split of one tour among k robots (the order itself: :mod:`planners.coverage.tour`)."""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import linear_sum_assignment


def split_tour(
    work: np.ndarray, hop: np.ndarray, to_entry: np.ndarray, to_exit: np.ndarray
) -> list[list[int]]:
    """Cut a tour of n tasks into k contiguous pieces (lists of tour positions, one per robot)
    minimizing the makespan.

    ``work[i]`` is the time to drive task i, ``hop[i]`` the time from task i − 1 to task i,
    ``to_entry[i, r]`` / ``to_exit[i, r]`` the time from robot r's start to task i's entry /
    exit (k = ``to_entry.shape[1]``). A piece costs the time from the nearest start to its
    first task, its tasks' times and the hops between them; a dynamic program over cut points
    finds the cuts minimizing the largest piece, and the Hungarian method (scipy
    linear_sum_assignment) gives each robot the piece it reaches soonest, by either end. Each
    robot's set stays contiguous along the tour, so it is mostly one connected stretch of the
    floor.
    """
    n, k = to_entry.shape
    if n == 0:
        return [[] for _ in range(k)]
    hop = np.concatenate([[0.0], np.asarray(hop, dtype=float)[1:]])
    prefix = np.concatenate([[0.0], np.cumsum(work + hop)])
    approach = to_entry.min(axis=1)
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
    pieces = [list(range(bounds[m], bounds[m + 1])) for m in range(k)]
    travel = np.zeros((k, k))
    for m, piece in enumerate(pieces):
        if piece:
            travel[:, m] = np.minimum(to_entry[piece[0]], to_exit[piece[-1]])
    rows, cols = linear_sum_assignment(travel)
    return [pieces[c] for _, c in sorted(zip(rows, cols, strict=True))]
