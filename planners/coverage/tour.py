"""One robot's visiting order of sweep tasks, judged by path cost between their ends.

Every task can be driven in any of its variants, forwards or backwards, so ordering is an open
generalized TSP over directed pieces (one piece per task, its entry and exit depending on the
choice). The heuristic: greedy nearest entry from the start, then local search until no move
gains — 2-opt where reversing a stretch drives each of its tasks backwards (the asymmetric
form of Croes' 1958 move), Or-opt (Or 1976) moving a run of up to three tasks elsewhere,
forwards or reversed — alternating with an exact choice of every task's variant for the
current order (dynamic programming over the variants, Viterbi). Hop costs come from one matrix
over all task ends (:func:`planners.coverage.geodesic.path_costs`), so a hop through a door
is priced as the detour it is.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from planners.coverage.tasks import SweepTask

_EPS = 1e-9
_MAX_ROUNDS = 50
# local-search moves priced at once, as rows of one array
_CHUNK = 32


@dataclass(frozen=True)
class TaskEnds:
    """Entry/exit point and driven length of every option of every task, and the cost matrix
    over all points (symmetric: the local search reads a hop from either end), plus one last
    column: the cost of ending the tour at a point (set by
    :func:`plan_tour`). Option ``2·v + r`` of a task is its variant ``v``, reversed when
    ``r`` is 1; option ``o`` of task ``t`` is entry ``offset[t] + o`` of the flat arrays."""

    offset: np.ndarray
    count: np.ndarray
    entry: np.ndarray
    exit: np.ndarray
    length: np.ndarray
    cost: np.ndarray

    def options(self, t: int) -> slice:
        return slice(int(self.offset[t]), int(self.offset[t] + self.count[t]))


def end_points(tasks: Sequence[SweepTask]) -> np.ndarray:
    """All task ends as one (M, 2) array: per variant its first and its last point."""
    pts = [p for t in tasks for v in t.variants for p in (v[0], v[-1])]
    return np.array(pts, dtype=float).reshape(-1, 2)


def task_ends(tasks: Sequence[SweepTask], cost: np.ndarray) -> TaskEnds:
    """The :class:`TaskEnds` of ``tasks`` given a cost matrix over their :func:`end_points`
    (and any other points, e.g. robot starts, appended after them)."""
    count = np.array([2 * len(t.variants) for t in tasks], dtype=np.int64)
    offset = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int64)
    entry = np.arange(int(count.sum()), dtype=np.int64)
    exit_ = entry ^ 1
    length = np.repeat(
        [float(np.hypot(*np.diff(v, axis=0).T).sum()) for t in tasks for v in t.variants], 2
    )
    return TaskEnds(offset, count, entry, exit_, length, np.pad(cost, ((0, 0), (0, 1))))


def path_of(task: SweepTask, option: int) -> np.ndarray:
    v = task.variants[option // 2]
    return v[::-1] if option % 2 else v


def plan_tour(
    ids: Sequence[int],
    start: int,
    ends: TaskEnds,
    initial: Sequence[tuple[int, int]] = (),
    closed: bool = False,
) -> list[tuple[int, int]]:
    """(task id, option) in driving order for tasks ``ids``, starting at point ``start`` (and
    priced as coming back to it at the end when ``closed``).

    Without ``initial`` the tour starts greedy; with it, the tasks of ``ids`` not in
    ``initial`` are first added to it one by one where they lengthen it least.
    """
    if not ids:
        return []
    ends.cost[:, -1] = ends.cost[:, start] if closed else 0.0
    if initial:
        seq = np.array([ends.offset[t] + o for t, o in initial], dtype=np.int64)
        placed = {t for t, _ in initial}
        for t in ids:
            if t not in placed:
                seq = _insert(seq, t, start, ends)
    else:
        seq = _greedy(list(ids), start, ends)
    best = _total(seq, start, ends)
    for _ in range(_MAX_ROUNDS):
        seq = _two_opt(seq, start, ends)
        seq = _or_opt(seq, start, ends)
        seq = _choose_options(seq, start, ends)
        total = _total(seq, start, ends)
        if total > best - _EPS:
            break
        best = total
    task = np.searchsorted(ends.offset, seq, side="right") - 1
    return [(int(t), int(k - ends.offset[t])) for t, k in zip(task, seq, strict=True)]


def tour_cost(tour: Sequence[tuple[int, int]], start: int, ends: TaskEnds) -> float:
    """Hops plus driven length of a :func:`plan_tour` result (with its way back to the start
    when it was planned ``closed``)."""
    seq = np.array([ends.offset[t] + o for t, o in tour], dtype=np.int64)
    return _total(seq, start, ends)


def insert_run(
    tour: Sequence[tuple[int, int]],
    run: Sequence[tuple[int, int]],
    start: int,
    ends: TaskEnds,
    closed: bool = False,
) -> list[tuple[int, int]]:
    """``tour`` with ``run`` (a fixed (task, option) sequence, e.g. a room's own tour) put in
    whole, forwards or driven backwards, where it adds the least."""
    ends.cost[:, -1] = ends.cost[:, start] if closed else 0.0
    c = ends.cost
    seq = np.array([ends.offset[t] + o for t, o in tour], dtype=np.int64)
    block = np.array([ends.offset[t] + o for t, o in run], dtype=np.int64)
    src, dst = _points(seq, start, ends)
    best = None
    for b in (block, _reverse(block)):
        added = c[src, ends.entry[b[0]]] + c[ends.exit[b[-1]], dst] - c[src, dst]
        k = int(np.argmin(added))
        if best is None or added[k] < best[0]:
            best = (float(added[k]), k, b)
    assert best is not None
    _, k, b = best
    out = np.concatenate([seq[:k], b, seq[k:]])
    task = np.searchsorted(ends.offset, out, side="right") - 1
    return [(int(t), int(i - ends.offset[t])) for t, i in zip(task, out, strict=True)]


def _greedy(ids: list[int], start: int, ends: TaskEnds) -> np.ndarray:
    """Sequence of flat option indices: always the nearest entry of a task not yet taken."""
    opts = np.concatenate([np.arange(ends.offset[t], ends.offset[t] + ends.count[t]) for t in ids])
    task = np.concatenate([np.full(ends.count[t], t) for t in ids])
    left = np.ones(len(opts), dtype=bool)
    seq = []
    cur = start
    for _ in ids:
        d = np.where(left, ends.cost[cur, ends.entry[opts]], np.inf)
        k = int(np.argmin(d))
        seq.append(opts[k])
        left &= task != task[k]
        cur = ends.exit[opts[k]]
    return np.array(seq, dtype=np.int64)


def _points(seq: np.ndarray, start: int, ends: TaskEnds) -> tuple[np.ndarray, np.ndarray]:
    """For every hop of the tour (into position i, and the last one out of it): where it
    comes from (the start, then each exit) and where it goes (each entry, then the end
    column of the cost matrix: the start again for a closed tour, nowhere for an open one)."""
    end = ends.cost.shape[1] - 1
    return np.concatenate([[start], ends.exit[seq]]), np.append(ends.entry[seq], end)


def _total(seq: np.ndarray, start: int, ends: TaskEnds) -> float:
    """Hops plus driven length."""
    src, dst = _points(seq, start, ends)
    return float(ends.cost[src, dst].sum() + ends.length[seq].sum())


def _insert(seq: np.ndarray, t: int, start: int, ends: TaskEnds) -> np.ndarray:
    """``seq`` with task ``t`` (its best option) where it adds the least."""
    c = ends.cost
    src, dst = _points(seq, start, ends)
    sl = ends.options(t)
    into = c[src[:, None], ends.entry[sl][None, :]]
    out = c[ends.exit[sl][None, :], dst[:, None]]
    added = into + out - c[src, dst][:, None] + ends.length[sl][None, :]
    p, o = np.unravel_index(int(np.argmin(added)), added.shape)
    return np.insert(seq, int(p), ends.offset[t] + int(o))


def _reverse(run: np.ndarray) -> np.ndarray:
    """The run driven backwards: tasks in reverse order, each in its reversed option."""
    return run[::-1] ^ 1


def _columns(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """``rows[:, cols]``, taken a whole row at a time, which reads memory in order."""
    return np.take(rows, cols, axis=1)


def _two_opt(seq: np.ndarray, start: int, ends: TaskEnds) -> np.ndarray:
    """Reverse stretches ``seq[i..j]`` (each task driven backwards) while that shortens hops.

    Scans i upwards and takes, for the first i with a gain, the j that gains most (first
    improvement in i, best in j); the gains of ``_CHUNK`` consecutive i are computed at once.
    """
    c = ends.cost
    n = len(seq)
    improved = True
    while improved:
        improved = False
        src, dst = _points(seq, start, ends)
        after = c[src[1:], dst[1:]]
        i0 = 0
        while i0 < n:
            i = np.arange(i0, min(i0 + _CHUNK, n))
            old = c[src[i], dst[i]][:, None] + after[None, :]
            new = _columns(c[src[i]], src[1:]) + _columns(c[dst[i]], dst[1:])
            gain = np.where(np.arange(n)[None, :] >= i[:, None], old - new, -np.inf)
            j = np.argmax(gain, axis=1)
            hit = np.flatnonzero(gain[np.arange(len(i)), j] > _EPS)
            if not len(hit):
                i0 = int(i[-1]) + 1
                continue
            ii, jj = int(i[hit[0]]), int(j[hit[0]])
            seq = np.concatenate([seq[:ii], _reverse(seq[ii : jj + 1]), seq[jj + 1 :]])
            src, dst = _points(seq, start, ends)
            after = c[src[1:], dst[1:]]
            improved = True
            i0 = ii + 1
    return seq


def _or_opt(seq: np.ndarray, start: int, ends: TaskEnds) -> np.ndarray:
    """Move runs of 1–3 consecutive tasks (forwards or reversed) to a cheaper place.

    Hop ``k`` of the tour runs from ``src[k]`` to ``dst[k]``; taking out the run
    ``seq[i : i + length]`` removes hops ``i .. i + length`` and adds one from ``src[i]`` to
    ``dst[i + length]``, and the run can go into any hop of what is left. Scans i upwards and
    moves the first run that gains to its best place (its cheapest hop), then goes on from the
    same i; the moves of ``_CHUNK`` consecutive runs are priced at once."""
    c = ends.cost
    improved = True
    while improved:
        improved = False
        for length in (1, 2, 3):
            src, dst = _points(seq, start, ends)
            base = c[src, dst]
            i0 = 0
            while i0 + length <= len(seq):
                i = np.arange(i0, min(i0 + _CHUNK, len(seq) - length + 1))
                rows = np.arange(len(i))
                a, b = src[i], dst[i + length]
                s_in, s_out = dst[i], src[i + length]
                removed = c[a, s_in] + c[s_out, b] - c[a, b]
                # hops from the tour's points into the run read from the run's end: the same
                # cost (the matrix is symmetric) in rows rather than columns, several times faster
                row_in, row_out = c[s_in], c[s_out]
                fwd = _columns(row_in, src) + _columns(row_out, dst) - base
                rev = _columns(row_out, src) + _columns(row_in, dst) - base
                fwd[rows, i] = removed
                rev[rows, i] = c[a, s_out] + c[s_in, b] - c[a, b]
                cand = np.minimum(fwd, rev)
                for d in range(1, length + 1):
                    cand[rows, i + d] = np.inf
                k = np.argmin(cand, axis=1)
                hit = np.flatnonzero(cand[rows, k] < removed - _EPS)
                if not len(hit):
                    i0 = int(i[-1]) + 1
                    continue
                h = int(hit[0])
                ii, kk = int(i[h]), int(k[h])
                run = seq[ii : ii + length]
                if rev[h, kk] < fwd[h, kk]:
                    run = _reverse(run)
                rest = np.concatenate([seq[:ii], seq[ii + length :]])
                p = kk if kk <= ii else kk - length
                seq = np.concatenate([rest[:p], run, rest[p:]])
                src, dst = _points(seq, start, ends)
                base = c[src, dst]
                improved = True
                i0 = ii
    return seq


def _choose_options(seq: np.ndarray, start: int, ends: TaskEnds) -> np.ndarray:
    """The option of every task (order fixed) minimizing hops plus driven length (Viterbi)."""
    c = ends.cost
    task = np.searchsorted(ends.offset, seq, side="right") - 1
    sl = ends.options(int(task[0]))
    cost = c[start, ends.entry[sl]] + ends.length[sl]
    back = []
    for p, t in itertools.pairwise(task):
        sp, st = ends.options(int(p)), ends.options(int(t))
        hop = c[np.ix_(ends.exit[sp], ends.entry[st])]
        total = cost[:, None] + hop + ends.length[st][None, :]
        back.append(np.argmin(total, axis=0))
        cost = total.min(axis=0)
    last = ends.options(int(task[-1]))
    k = int(np.argmin(cost + c[ends.exit[last], -1]))
    picks = [k]
    for b in reversed(back):
        k = int(b[k])
        picks.append(k)
    picks.reverse()
    return ends.offset[task] + np.array(picks, dtype=np.int64)
