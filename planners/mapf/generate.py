"""Seeded benchmark maps and scenarios in the spirit of the MovingAI MAPF suite (Stern et al. 2019).

Map families (all ``free`` masks, True = passable): uniformly random obstacles, rooms joined by
doors, a maze with two-cell-wide corridors, and a warehouse of shelf blocks. Scenarios draw
distinct starts and distinct goals uniformly from the largest 4-connected component, so every
prefix of agents passes the feasibility check. Same seed, same output.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from planners.mapf.model import MapfInstance


def random_map(rows: int, cols: int, obstacle_ratio: float, seed: int) -> np.ndarray:
    """Exactly ``round(ratio · rows · cols)`` obstacle cells placed uniformly at random."""
    rng = np.random.default_rng(seed)
    free = np.ones(rows * cols, dtype=bool)
    free[rng.choice(rows * cols, size=round(obstacle_ratio * rows * cols), replace=False)] = False
    return free.reshape(rows, cols)


def room_map(size: int, room: int, seed: int) -> np.ndarray:
    """Square rooms of ``room × room`` cells separated by one-cell walls, one door per wall."""
    rng = np.random.default_rng(seed)
    free = np.ones((size, size), dtype=bool)
    pitch = room + 1
    walls = np.arange(room, size - 1, pitch)
    free[walls, :] = False
    free[:, walls] = False
    for r0 in range(0, size, pitch):
        for c0 in range(0, size, pitch):
            if c0 + room < size - 1:
                free[r0 + rng.integers(min(room, size - r0)), c0 + room] = True
            if r0 + room < size - 1:
                free[r0 + room, c0 + rng.integers(min(room, size - c0))] = True
    return free


def maze_map(size: int, corridor: int, seed: int) -> np.ndarray:
    """A perfect maze (randomized depth-first search) with ``corridor``-wide passages."""
    rng = np.random.default_rng(seed)
    pitch = corridor + 1
    n = (size - 1) // pitch
    free = np.zeros((size, size), dtype=bool)
    visited = np.zeros((n, n), dtype=bool)

    def open_block(r: int, c: int) -> None:
        free[1 + r * pitch : 1 + r * pitch + corridor, 1 + c * pitch : 1 + c * pitch + corridor] = (
            True
        )

    stack = [(0, 0)]
    visited[0, 0] = True
    open_block(0, 0)
    while stack:
        r, c = stack[-1]
        options = [
            (r + dr, c + dc)
            for dr, dc in ((0, 1), (1, 0), (0, -1), (-1, 0))
            if 0 <= r + dr < n and 0 <= c + dc < n and not visited[r + dr, c + dc]
        ]
        if not options:
            stack.pop()
            continue
        nr, nc = options[rng.integers(len(options))]
        visited[nr, nc] = True
        open_block(nr, nc)
        top, left = 1 + min(r, nr) * pitch, 1 + min(c, nc) * pitch
        if nr != r:
            free[top + corridor, left : left + corridor] = True
        else:
            free[top : top + corridor, left + corridor] = True
        stack.append((nr, nc))
    return free


def warehouse_map(rows: int, cols: int, shelf_length: int = 7, aisle: int = 2) -> np.ndarray:
    """Two-cell-deep shelf blocks in rows, ``aisle``-wide aisles, a three-cell free border."""
    free = np.ones((rows, cols), dtype=bool)
    for r in range(3, rows - 4, 2 + aisle):
        for c in range(3, cols - 3 - shelf_length + 1, shelf_length + aisle):
            free[r : r + 2, c : c + shelf_length] = False
    return free


def random_instance(free: np.ndarray, k: int, seed: int) -> MapfInstance:
    """``k`` agents with distinct starts and goals in the largest connected component."""
    labels, count = ndimage.label(free)
    if count == 0:
        raise ValueError("the map has no free cell")
    sizes = np.bincount(labels.ravel())[1:]
    cells = np.argwhere(labels == 1 + int(np.argmax(sizes)))
    if k > len(cells):
        raise ValueError(f"{k} agents do not fit in a component of {len(cells)} cells")
    rng = np.random.default_rng(seed)
    starts = cells[rng.permutation(len(cells))[:k]]
    goals = cells[rng.permutation(len(cells))[:k]]
    return MapfInstance(free, tuple(map(tuple, starts)), tuple(map(tuple, goals)))


def benchmark_maps(seed: int = 0) -> dict[str, np.ndarray]:
    """The maps of ``fleet bench mapf``: 32 × 32 each, generated here (``gen-``), so they are
    not the MovingAI benchmark's maps of similar kinds and figures measured on those do not
    apply to them. The names before were random-32-32-10, random-32-32-20, room-32-32-7,
    maze-32-32-2 and warehouse-32-32, in this order."""
    return {
        "gen-random-10pct": random_map(32, 32, 0.10, seed),
        "gen-random-20pct": random_map(32, 32, 0.20, seed + 1),
        "gen-rooms-7x7": room_map(32, 7, seed + 2),
        "gen-maze-2wide": maze_map(32, 2, seed + 3),
        "gen-shelves": warehouse_map(32, 32),
    }
