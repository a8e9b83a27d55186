"""Boustrophedon lanes over a grid split among k robots: the baseline of `fleet bench coverage`.

The free space a robot centre may use (clearance ≥ the robot's radius, connected to a start) is
split into k vertical strips of equal area; each strip is swept by horizontal lanes spaced the
robot's ``cleaning_width · (1 − overlap)`` apart, plus one extra lane on each side of every row
where the free space changes shape (an obstacle edge), so the swath reaches along furniture too.
Lane segments are chained greedily from the robot's start, nearest endpoint first (the ordering
of boustrophedon coverage, Choset 2000), with transitions that are straight where the straight
line is free and A* on the grid where it is not.
"""

from __future__ import annotations

import heapq
import itertools
import math

import numpy as np
from scipy import ndimage

from planners.grid import GridMap
from planners.polyline import simplify
from planners.robot import RobotSpec

SHAPE_CHANGE_CELLS = 3


def free_centres(grid: GridMap, starts: np.ndarray, robot_radius: float) -> np.ndarray:
    """Cells a robot centre may occupy, connected to one of the starts."""
    blocked = grid.occupied | grid.unknown
    clear = ndimage.distance_transform_edt(~blocked) * grid.resolution - grid.resolution / 2
    ok = clear >= robot_radius
    labels, _ = ndimage.label(ok, structure=np.ones((3, 3)))
    rc = grid.world_to_cell(starts)
    rc = rc[grid.in_bounds(rc)]
    ids = sorted({int(labels[r, c]) for r, c in rc} - {0})
    if not ids:
        # A start just inside the clearance margin: take the component nearest to it.
        _, (ir, ic) = ndimage.distance_transform_edt(labels == 0, return_indices=True)
        ids = sorted({int(labels[ir[r, c], ic[r, c]]) for r, c in rc})
    return np.isin(labels, ids)


def split_strips(free: np.ndarray, k: int) -> list[np.ndarray]:
    """k masks of vertical strips with equal numbers of free cells."""
    per_col = free.sum(axis=0)
    cum = np.cumsum(per_col)
    bounds = (
        [0] + [int(np.searchsorted(cum, cum[-1] * i / k)) for i in range(1, k)] + [free.shape[1]]
    )
    out = []
    for a, b in itertools.pairwise(bounds):
        m = np.zeros_like(free)
        m[:, a:b] = free[:, a:b]
        out.append(m)
    return out


def lane_rows(mask: np.ndarray, spacing_cells: float) -> list[int]:
    """Rows to sweep: regular spacing from the lowest free row, plus both sides of shape changes."""
    rows = np.nonzero(mask.any(axis=1))[0]
    if len(rows) == 0:
        return []
    lo, hi = int(rows[0]), int(rows[-1])
    chosen = {round(r) for r in np.arange(lo, hi + 1e-9, spacing_cells)} | {hi}
    diff = (mask[1:] != mask[:-1]).sum(axis=1)
    for r in np.nonzero(diff > SHAPE_CHANGE_CELLS)[0]:
        for row in (int(r), int(r) + 1):
            if mask[row].any() and min(abs(row - c) for c in chosen) > spacing_cells / 3:
                chosen.add(row)
    return sorted(chosen)


def lane_segments(mask: np.ndarray, rows: list[int]) -> list[tuple[int, int, int]]:
    """(row, col_start, col_end) runs of free cells on each lane row."""
    segs = []
    for r in rows:
        line = np.concatenate([[False], mask[r], [False]]).astype(np.int8)
        d = np.diff(line)
        for a, b in zip(np.nonzero(d == 1)[0], np.nonzero(d == -1)[0] - 1, strict=True):
            segs.append((r, int(a), int(b)))
    return segs


def astar(free: np.ndarray, start: tuple[int, int], goal: tuple[int, int]) -> list[tuple[int, int]]:
    """8-connected A* with the octile heuristic (Hart, Nilsson, Raphael 1968); [] if unreachable."""
    rows, cols = free.shape
    moves = [(dr, dc, math.hypot(dr, dc)) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if dr or dc]
    g = {start: 0.0}
    parent: dict[tuple[int, int], tuple[int, int]] = {}
    heap = [(0.0, start)]
    closed = set()
    while heap:
        _, cur = heapq.heappop(heap)
        if cur == goal:
            path = [cur]
            while cur in parent:
                cur = parent[cur]
                path.append(cur)
            return path[::-1]
        if cur in closed:
            continue
        closed.add(cur)
        for dr, dc, cost in moves:
            nr, nc = cur[0] + dr, cur[1] + dc
            if not (0 <= nr < rows and 0 <= nc < cols) or not free[nr, nc]:
                continue
            if dr and dc and not (free[cur[0] + dr, cur[1]] and free[cur[0], cur[1] + dc]):
                continue
            ng = g[cur] + cost
            if ng < g.get((nr, nc), math.inf):
                g[(nr, nc)] = ng
                parent[(nr, nc)] = cur
                h = max(abs(goal[0] - nr), abs(goal[1] - nc)) + (math.sqrt(2) - 1) * min(
                    abs(goal[0] - nr), abs(goal[1] - nc)
                )
                heapq.heappush(heap, (ng + h, (nr, nc)))
    return []


def line_free(free: np.ndarray, a: tuple[int, int], b: tuple[int, int]) -> bool:
    n = max(abs(b[0] - a[0]), abs(b[1] - a[1]), 1) * 2
    r = np.rint(np.linspace(a[0], b[0], n + 1)).astype(int)
    c = np.rint(np.linspace(a[1], b[1], n + 1)).astype(int)
    return bool(free[r, c].all())


def transition(free: np.ndarray, a: tuple[int, int], b: tuple[int, int]) -> list[tuple[int, int]]:
    """Cells from a to b: the straight line if free, else a simplified A* path."""
    if line_free(free, a, b):
        return [a, b]
    path = astar(free, a, b)
    if not path:
        return []
    pts = simplify(np.array(path, dtype=float), 0.7)
    out = [tuple(int(v) for v in pts[0])]
    for p in pts[1:]:
        q = tuple(int(v) for v in p)
        if not line_free(free, out[-1], q):
            # simplification cut a corner: keep the raw A* cells between them
            i, j = path.index(out[-1]), path.index(q)
            out.extend(path[i + 1 : j])
        out.append(q)
    return out


def plan_lanes(
    grid: GridMap, starts: list[tuple[float, float]], robot: RobotSpec, overlap: float
) -> list[np.ndarray]:
    """One waypoint path (N, 2) in world metres per start, for ``robot`` with lanes sharing
    ``overlap`` of its cleaning width."""
    free = free_centres(grid, np.array(starts, dtype=float), robot.radius)
    strips = split_strips(free, len(starts))
    spacing = math.floor(robot.cleaning_width * (1 - overlap) / grid.resolution + 1e-9)
    # Give each robot the strip whose free cells are nearest its start, in order of start x.
    order = np.argsort([s[0] for s in starts], kind="stable")
    paths: list[np.ndarray] = [np.zeros((0, 2))] * len(starts)
    for strip, i in zip(strips, order, strict=True):
        segs = lane_segments(strip, lane_rows(strip, spacing))
        cur = tuple(int(v) for v in grid.world_to_cell(np.array(starts[i])))
        if not free[cur]:
            cand = np.argwhere(free)
            cur = tuple(int(v) for v in cand[np.argmin(np.abs(cand - cur).sum(axis=1))])
        cells = [cur]
        todo = list(range(len(segs)))
        while todo:
            ends = np.array([[segs[j][0], segs[j][e]] for j in todo for e in (1, 2)])
            d = np.hypot(ends[:, 0] - cur[0], ends[:, 1] - cur[1])
            # prefer the same or next lane: nearest endpoint, rows weighted double
            d += np.abs(ends[:, 0] - cur[0])
            k = int(np.argmin(d))
            j = todo.pop(k // 2)
            r, c0, c1 = segs[j]
            a, b = ((r, c0), (r, c1)) if k % 2 == 0 else ((r, c1), (r, c0))
            hop = transition(free, cur, a)
            cells.extend(hop[1:] if hop else [a])
            cells.append(b)
            cur = b
        paths[i] = grid.cell_to_world(np.array(cells))
    return paths
