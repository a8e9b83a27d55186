"""Visiting order of rooms and tasks, and the split of one tour among k robots."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment

from planners.coverage.tasks import SweepTask


def two_opt_path(dist: np.ndarray, start: int) -> list[int]:
    """An open tour of all nodes from ``start``: nearest neighbour, then 2-opt until no gain.

    2-opt (Croes 1958) on a path: reversing ``tour[i:j+1]`` changes only the edges into ``i``
    and out of ``j`` (there is no edge out of the last node).
    """
    n = len(dist)
    tour = [start]
    left = set(range(n)) - {start}
    while left:
        nxt = min(left, key=lambda k: dist[tour[-1], k])
        tour.append(nxt)
        left.remove(nxt)
    improved = True
    while improved:
        improved = False
        for i in range(1, n - 1):
            for j in range(i + 1, n):
                a, b = tour[i - 1], tour[i]
                c = tour[j]
                d = tour[j + 1] if j + 1 < n else None
                before = dist[a, b] + (dist[c, d] if d is not None else 0.0)
                after = dist[a, c] + (dist[b, d] if d is not None else 0.0)
                if after < before - 1e-9:
                    tour[i : j + 1] = tour[i : j + 1][::-1]
                    improved = True
    return tour


def order_tasks(tasks: Sequence[SweepTask], p: np.ndarray) -> list[SweepTask]:
    """Tasks in an order with short hops from each task's exit to the next one's entry.

    Every task has variants (ways to drive it) whose reversals are variants too, so the order
    is an open tour over directed pieces: greedy nearest entry from ``p``, then 2-opt where
    reversing a stretch drives each of its tasks backwards (the asymmetric-endpoint form of
    Croes' move). The variants are chosen afterwards by :func:`choose_variants`.
    """
    n = len(tasks)
    if n <= 1:
        return list(tasks)
    starts = [np.array([v[0] for v in t.variants]) for t in tasks]
    ends = [np.array([v[-1] for v in t.variants]) for t in tasks]
    seq: list[tuple[int, int]] = []
    left = set(range(n))
    cur = np.asarray(p, dtype=float)
    while left:
        best = min(
            ((k, v) for k in left for v in range(len(starts[k]))),
            key=lambda kv: float(np.hypot(*(starts[kv[0]][kv[1]] - cur))),
        )
        seq.append(best)
        left.remove(best[0])
        cur = ends[best[0]][best[1]]
    s = np.array([starts[k][v] for k, v in seq])
    e = np.array([ends[k][v] for k, v in seq])
    s = np.vstack([[np.nan, np.nan], s])
    e = np.vstack([np.asarray(p, dtype=float)[None, :], e])
    order = list(range(n + 1))

    def d(a: np.ndarray, b: np.ndarray) -> float:
        return float(np.hypot(*(a - b)))

    improved = True
    while improved:
        improved = False
        for i in range(1, n):
            for j in range(i + 1, n + 1):
                a, b, c = order[i - 1], order[i], order[j]
                nxt = order[j + 1] if j < n else None
                before = d(e[a], s[b]) + (d(e[c], s[nxt]) if nxt is not None else 0.0)
                after = d(e[a], e[c]) + (d(s[b], s[nxt]) if nxt is not None else 0.0)
                if after < before - 1e-9:
                    seg = order[i : j + 1][::-1]
                    for k in seg:
                        s[k], e[k] = e[k].copy(), s[k].copy()
                    order[i : j + 1] = seg
                    improved = True
    return [tasks[seq[k - 1][0]] for k in order[1:]]


def choose_variants(tasks: Sequence[SweepTask], p: np.ndarray) -> list[np.ndarray]:
    """The variant of each task (in the given order) minimizing the total straight-line hop
    length from ``p`` through all tasks: dynamic programming over the variants (Viterbi)."""
    if not tasks:
        return []
    cost = np.array([float(np.hypot(*(v[0] - p))) for v in tasks[0].variants])
    back: list[np.ndarray] = []
    for prev, cur in itertools.pairwise(tasks):
        ends = np.array([v[-1] for v in prev.variants])
        begins = np.array([v[0] for v in cur.variants])
        hop = np.hypot(*(ends[:, None, :] - begins[None, :, :]).transpose(2, 0, 1))
        total = cost[:, None] + hop
        back.append(np.argmin(total, axis=0))
        cost = total.min(axis=0)
    k = int(np.argmin(cost))
    picks = [k]
    for b in reversed(back):
        k = int(b[k])
        picks.append(k)
    picks.reverse()
    return [t.variants[i] for t, i in zip(tasks, picks, strict=True)]


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
