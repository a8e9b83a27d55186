"""Room segmentation of the reachable floor, distance-transform based.

Following the distance-transform method compared by Bormann et al. (ICRA 2016, "Room
segmentation: survey, implementation, and analysis"): the cells farther than a threshold from any
obstacle fall into separate "cores" where openings are narrower than twice the threshold. The
threshold is raised from half a door width in 5 cm steps and the one giving the most cores of at
least ``MIN_CORE_AREA`` is kept; each core seeds a room, and every reachable cell joins the
geodesically nearest core (multi-source Dijkstra on the 8-connected grid). Rooms smaller than a
minimum area join the neighbour they share the longest border with.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

MIN_CORE_AREA = 0.25


def grid_graph(mask: np.ndarray) -> tuple[coo_matrix, np.ndarray]:
    """Sparse 8-connected graph of the True cells (no diagonal past a blocked corner), and the
    node index of every cell (−1 outside)."""
    index = np.full(mask.shape, -1, dtype=np.int64)
    index[mask] = np.arange(int(mask.sum()))
    src, dst, w = [], [], []
    rows, cols = mask.shape
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = mask[: rows - dr, max(0, -dc) : cols - max(0, dc)]
        b = mask[dr:, max(0, dc) : cols + min(0, dc) or None]
        ok = a & b
        if dr and dc:
            side1 = mask[: rows - dr, max(0, dc) : cols + min(0, dc) or None]
            side2 = mask[dr:, max(0, -dc) : cols - max(0, dc)]
            ok &= side1 & side2
        ia = index[: rows - dr, max(0, -dc) : cols - max(0, dc)][ok]
        ib = index[dr:, max(0, dc) : cols + min(0, dc) or None][ok]
        src.append(ia)
        dst.append(ib)
        w.append(np.full(len(ia), math.sqrt(2.0) if dr and dc else 1.0))
    n = int(mask.sum())
    s, d, ww = np.concatenate(src), np.concatenate(dst), np.concatenate(w)
    graph = coo_matrix(
        (np.concatenate([ww, ww]), (np.concatenate([s, d]), np.concatenate([d, s]))), shape=(n, n)
    )
    return graph, index


def segment_rooms(
    reach: np.ndarray,
    clearance_m: np.ndarray,
    resolution: float,
    door_width: float,
    min_room_area: float,
) -> np.ndarray:
    """Room labels (1..n, 0 outside ``reach``) of the reachable robot-centre cells."""
    cores, n_cores = _best_cores(reach, clearance_m, resolution, door_width)
    parts, n_parts = ndimage.label(reach)
    seeded = np.unique(parts[cores > 0])
    for p in sorted(set(range(1, n_parts + 1)) - set(seeded.tolist())):
        n_cores += 1
        cores[parts == p] = n_cores
    graph, index = grid_graph(reach)
    seed_cells = index[cores > 0]
    seed_label = cores[cores > 0]
    _, _, sources = dijkstra(
        graph.tocsr(), indices=seed_cells, min_only=True, return_predecessors=True
    )
    label_of_node = np.zeros(len(sources), dtype=np.int32)
    pos = np.full(len(sources), -1)
    pos[seed_cells] = np.arange(len(seed_cells))
    ok = sources >= 0
    label_of_node[ok] = seed_label[pos[sources[ok]]]
    labels = np.zeros(reach.shape, dtype=np.int32)
    labels[reach] = label_of_node
    return _merge_small(labels, math.ceil(min_room_area / resolution**2))


def _best_cores(
    reach: np.ndarray, clearance_m: np.ndarray, resolution: float, door_width: float
) -> tuple[np.ndarray, int]:
    """Core labels at the threshold that yields the most cores of at least ``MIN_CORE_AREA``."""
    min_cells = MIN_CORE_AREA / resolution**2
    inside = np.where(reach, clearance_m, 0.0)
    best: tuple[int, float] = (-1, door_width / 2)
    for t in np.arange(door_width / 2, max(float(inside.max()), door_width / 2), 0.05):
        labels, n = ndimage.label(inside > t, structure=np.ones((3, 3)))
        count = int((np.bincount(labels.ravel())[1:] >= min_cells).sum()) if n else 0
        if count > best[0]:
            best = (count, float(t))
    labels, n = ndimage.label(inside > best[1], structure=np.ones((3, 3)))
    sizes = np.bincount(labels.ravel())
    keep = np.flatnonzero(sizes >= min_cells)
    keep = keep[keep > 0]
    lut = np.zeros(n + 1, dtype=np.int32)
    lut[keep] = np.arange(1, len(keep) + 1)
    return lut[labels], len(keep)


def shared_borders(labels: np.ndarray) -> dict[tuple[int, int], int]:
    """Number of 4-neighbour cell pairs between every two different non-zero labels."""
    pairs = []
    for a, b in ((labels[:, :-1], labels[:, 1:]), (labels[:-1, :], labels[1:, :])):
        ok = (a != b) & (a > 0) & (b > 0)
        lo = np.minimum(a[ok], b[ok]).astype(np.int64)
        hi = np.maximum(a[ok], b[ok]).astype(np.int64)
        pairs.append(lo * (1 << 31) + hi)
    codes, counts = np.unique(np.concatenate(pairs), return_counts=True)
    mask = (1 << 31) - 1
    return {(int(c >> 31), int(c & mask)): int(k) for c, k in zip(codes, counts, strict=True)}


def _merge_small(labels: np.ndarray, min_cells: int) -> np.ndarray:
    """Merge rooms below ``min_cells`` into their longest-border neighbour; relabel 1..n."""
    while True:
        ids, sizes = np.unique(labels[labels > 0], return_counts=True)
        small = ids[sizes < min_cells]
        if len(small) == 0 or len(ids) == 1:
            break
        borders = shared_borders(labels)
        target = small[np.argmin(sizes[sizes < min_cells])]
        best, best_len = 0, 0
        for (a, b), k in borders.items():
            if target in (a, b) and k > best_len:
                best, best_len = (b if a == target else a), k
        if best == 0:
            break
        labels[labels == target] = best
    ids = np.unique(labels[labels > 0])
    lut = np.zeros(int(labels.max()) + 1, dtype=np.int32)
    lut[ids] = np.arange(1, len(ids) + 1)
    return lut[labels]
