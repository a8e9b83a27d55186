"""The transit graph: coarse cells of a floor plan that one robot occupies alone, for planning
transits in space and time (``planners.deconfliction``).

Construction, from an occupancy grid (``GridMap``) and a disc robot's radius plus a clearance:

- **Cells.** The floor is cut into square coarse cells of about the robot's diameter plus the
  clearance on each side (``2 · (radius + clearance)``, rounded up to whole fine cells), a
  coarse grid over the fine one in the spirit of the cell decompositions of roadmap planning
  (Latombe, "Robot Motion Planning", 1991, ch. 5 and 6).
- **Usable cells and their points.** A fine cell is a possible robot centre where its obstacle
  clearance (``planners.grid.clearance``) is at least ``radius + clearance``. A coarse cell is
  usable when it holds such a centre; its point (where a robot stands in it) is the possible
  centre nearest the cell's geometric centre. Where two usable cells' points lie closer than
  ``2 · (radius + clearance)`` (a narrow passage whose centre line runs along a cell border)
  only one is kept, the one whose point is nearer its own cell's centre (ties: lower index), so
  robots standing at the points of different cells never overlap and a one-robot-wide corridor
  is one chain of cells, not two side by side.
- **Adjacency.** Two 4-adjacent usable cells are joined when a robot centre can move from one
  point to the other through possible centres inside the two cells alone (a 4-connected path of
  fine cells in their union). A corridor one robot wide is thus a chain of single cells, each
  joined only to the next.
- **Locating.** A world point maps to the usable cell whose point is nearest among the cells in
  the same connected region of possible centres as the point and in that region's largest
  component of the graph (a point off every region: the nearest usable cell). A region's cells
  outside that component (a pocket whose only way out runs diagonally or through a cell
  dropped for spacing) are not located to, so robots of one region can always reach each
  other's cells.

Every step is numpy / scipy over the whole grid (connected components by
``scipy.sparse.csgraph``), built once per floor plan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from planners.grid import GridMap, clearance
from planners.mapf.grid_graph import GridGraph

Cell = tuple[int, int]


@dataclass(frozen=True, eq=False)
class TransitGraph:
    """Coarse cells (``usable[r, c]``), their world points, and the moves between them.

    ``open_right[r, c]`` joins ``(r, c)`` and ``(r, c + 1)``, ``open_down[r, c]`` joins ``(r, c)``
    and ``(r + 1, c)`` (row 0 at the lowest y, as in ``GridMap``). ``component[r, c]`` is the
    connected component of a usable cell (-1 elsewhere). ``graph`` is the same graph for the
    MAPF solvers (``planners.mapf``), with its distance cache.
    """

    usable: np.ndarray
    points: np.ndarray  # (rows, cols, 2) world x, y of each usable cell's point; nan elsewhere
    open_right: np.ndarray
    open_down: np.ndarray
    component: np.ndarray
    cell_size: float
    origin: tuple[float, float]
    radius: float
    clearance: float
    graph: GridGraph
    fine_resolution: float
    fine_region: np.ndarray  # connected region of possible centres per fine cell, -1 elsewhere
    cell_region: np.ndarray  # that region at each usable cell's point, -1 elsewhere
    primary: np.ndarray  # usable cells in their region's largest component (located to)

    @property
    def shape(self) -> tuple[int, int]:
        return self.usable.shape  # type: ignore[return-value]

    @property
    def num_cells(self) -> int:
        """The number of usable cells."""
        return int(self.usable.sum())

    def degree(self) -> np.ndarray:
        """The number of neighbours of each cell (0 for unusable cells)."""
        deg = np.zeros(self.shape, dtype=np.int64)
        deg[:, :-1] += self.open_right
        deg[:, 1:] += self.open_right
        deg[:-1, :] += self.open_down
        deg[1:, :] += self.open_down
        return deg

    def joined(self, a: Cell, b: Cell) -> bool:
        """Whether a robot may move between the 4-adjacent cells ``a`` and ``b``."""
        (r0, c0), (r1, c1) = sorted((tuple(a), tuple(b)))
        if r0 == r1 and c1 == c0 + 1:
            return bool(self.open_right[r0, c0])
        if c0 == c1 and r1 == r0 + 1:
            return bool(self.open_down[r0, c0])
        return False

    def point(self, cell: Cell) -> tuple[float, float]:
        """The world point (x, y) of a usable cell."""
        r, c = cell
        if not self.usable[r, c]:
            raise ValueError(f"cell {cell} is not usable")
        return float(self.points[r, c, 0]), float(self.points[r, c, 1])

    def candidates(self, xy: np.ndarray, k: int = 8) -> list[list[Cell]]:
        """For each world point, up to ``k`` usable cells, nearest first, of the point's own
        region of possible centres (all usable cells if the point lies in none); empty when no
        usable cell is in its region."""
        xy = np.atleast_2d(np.asarray(xy, dtype=float))
        cells = np.argwhere(self.usable)
        if len(cells) == 0:
            return [[] for _ in xy]
        pts = self.points[cells[:, 0], cells[:, 1]]
        regions = np.where(
            self.primary[cells[:, 0], cells[:, 1]], self.cell_region[cells[:, 0], cells[:, 1]], -2
        )
        fine = np.floor((xy[:, ::-1] - np.array(self.origin)[::-1]) / self.fine_resolution)
        fine = fine.astype(np.int64)
        rows, cols = self.fine_region.shape
        inside = (fine[:, 0] >= 0) & (fine[:, 0] < rows) & (fine[:, 1] >= 0) & (fine[:, 1] < cols)
        own = np.full(len(xy), -1, dtype=np.int64)
        own[inside] = self.fine_region[fine[inside, 0], fine[inside, 1]]
        out: list[list[Cell]] = []
        for p, region in zip(xy, own, strict=True):
            pool = np.nonzero(regions == region)[0] if region >= 0 else np.arange(len(cells))
            if region >= 0 and len(pool) == 0:
                out.append([])
                continue
            d = np.hypot(*(pts[pool] - p).T)
            best = pool[np.argsort(d, kind="stable")[:k]]
            out.append([(int(r), int(c)) for r, c in cells[best]])
        return out

    def locate(self, xy: np.ndarray) -> list[Cell | None]:
        """The usable cell of each world point (see the module's locating rule), or None."""
        return [c[0] if c else None for c in self.candidates(xy, 1)]


def _components(ok: np.ndarray, group: np.ndarray) -> np.ndarray:
    """Connected components (flat labels) of the ``ok`` cells of a grid, 4-adjacent cells joined
    only inside the same ``group`` id; cells outside ``ok`` get -1."""
    rows, cols = ok.shape
    idx = np.arange(rows * cols).reshape(rows, cols)
    right = ok[:, :-1] & ok[:, 1:] & (group[:, :-1] == group[:, 1:])
    down = ok[:-1, :] & ok[1:, :] & (group[:-1, :] == group[1:, :])
    a = np.concatenate([idx[:, :-1][right], idx[:-1, :][down]])
    b = np.concatenate([idx[:, 1:][right], idx[1:, :][down]])
    n = rows * cols
    adjacency = coo_matrix((np.ones(a.size), (a, b)), shape=(n, n)).tocsr()
    _, labels = connected_components(adjacency, directed=False)
    return np.where(ok.ravel(), labels, -1)


def build_transit_graph(
    grid: GridMap, radius: float, clearance_m: float, cell_size: float | None = None
) -> TransitGraph:
    """The transit graph of ``grid`` for a disc robot of ``radius`` keeping ``clearance_m`` from
    obstacles and from other robots; ``cell_size`` defaults to ``2 · (radius + clearance_m)``.
    """
    if radius <= 0 or clearance_m < 0:
        raise ValueError(f"need radius > 0 and clearance ≥ 0, got {radius}, {clearance_m}")
    spacing = 2.0 * (radius + clearance_m)
    size = spacing if cell_size is None else cell_size
    res = grid.resolution
    k = max(1, math.ceil(size / res - 1e-9))
    rows, cols = grid.shape
    crow, ccol = -(-rows // k), -(-cols // k)
    ok = np.zeros((crow * k, ccol * k), dtype=bool)
    ok[:rows, :cols] = clearance(grid) >= radius + clearance_m - 1e-9

    # each coarse cell's point: the possible centre nearest its geometric centre
    off = (np.arange(k) + 0.5) - k / 2.0
    d2 = (off[:, None] ** 2 + off[None, :] ** 2).ravel()
    blocks = ok.reshape(crow, k, ccol, k).transpose(0, 2, 1, 3).reshape(crow, ccol, k * k)
    score = np.where(blocks, d2[None, None, :], np.inf)
    best = np.argmin(score, axis=2)
    usable = blocks.any(axis=2)
    fr = np.arange(crow)[:, None] * k + best // k
    fc = np.arange(ccol)[None, :] * k + best % k
    x = grid.origin[0] + (fc + 0.5) * res
    y = grid.origin[1] + (fr + 0.5) * res
    usable = _spaced(usable, x, y, np.min(score, axis=2), spacing)

    points = np.full((crow, ccol, 2), np.nan)
    points[usable, 0] = x[usable]
    points[usable, 1] = y[usable]
    rep = (fr * (ccol * k) + fc).astype(np.int64)  # flat fine index of each cell's point
    open_right, open_down = _openings(ok, usable, rep, k)

    graph = GridGraph(usable, open_right, open_down)
    cidx = np.arange(crow * ccol).reshape(crow, ccol)
    a = np.concatenate([cidx[:, :-1][open_right], cidx[:-1, :][open_down]])
    b = np.concatenate([cidx[:, 1:][open_right], cidx[1:, :][open_down]])
    n = crow * ccol
    _, comp = connected_components(
        coo_matrix((np.ones(a.size), (a, b)), shape=(n, n)).tocsr(), directed=False
    )
    component = np.where(usable.ravel(), comp, -1).reshape(usable.shape)

    fine_region = _components(ok, np.zeros_like(ok, dtype=np.int64)).reshape(ok.shape)
    cell_region = np.where(usable, fine_region.ravel()[rep], -1)
    return TransitGraph(
        usable=usable,
        points=points,
        open_right=open_right,
        open_down=open_down,
        component=component,
        cell_size=k * res,
        origin=(float(grid.origin[0]), float(grid.origin[1])),
        radius=radius,
        clearance=clearance_m,
        graph=graph,
        fine_resolution=res,
        fine_region=fine_region,
        cell_region=cell_region,
        primary=_primary(usable, component, cell_region),
    )


def _spaced(
    usable: np.ndarray, x: np.ndarray, y: np.ndarray, score: np.ndarray, spacing: float
) -> np.ndarray:
    """The usable cells whose points (``x``, ``y``) stay at least ``spacing`` apart: where two
    are closer, the one whose point is nearer its own centre (lower ``score``; ties: lower index)
    is kept."""
    cells = np.argwhere(usable)
    pts = np.column_stack([x[usable], y[usable]])
    pairs = cKDTree(pts).query_pairs(spacing - 1e-9, output_type="ndarray") if len(pts) else []
    if not len(pairs):
        return usable
    rank = np.lexsort((np.arange(len(cells)), score[usable]))
    position = np.empty(len(cells), dtype=np.int64)
    position[rank] = np.arange(len(cells))
    close: dict[int, list[int]] = {}
    for i, j in pairs.tolist():
        close.setdefault(i, []).append(j)
        close.setdefault(j, []).append(i)
    dropped: set[int] = set()
    for i in sorted(close, key=lambda i: position[i]):
        if i in dropped:
            continue
        dropped.update(j for j in close[i] if position[j] > position[i])
    kept = usable.copy()
    for i in dropped:
        kept[cells[i, 0], cells[i, 1]] = False
    return kept


def _openings(
    ok: np.ndarray, usable: np.ndarray, rep: np.ndarray, k: int
) -> tuple[np.ndarray, np.ndarray]:
    """``open_right`` and ``open_down``: two 4-adjacent usable cells are joined where a way
    through possible centres (``ok``) inside the union of the two cells joins their points (flat
    fine indices ``rep``); ``k`` fine cells a side."""
    crow, ccol = usable.shape
    coarse_r = np.repeat(np.arange(crow), k)[:, None] * np.ones((1, ccol * k), dtype=np.int64)
    coarse_c = np.repeat(np.arange(ccol), k)[None, :] * np.ones((crow * k, 1), dtype=np.int64)
    open_right = np.zeros((crow, max(ccol - 1, 0)), dtype=bool)
    open_down = np.zeros((max(crow - 1, 0), ccol), dtype=bool)
    for parity in (0, 1):
        pair_c = (coarse_c - parity) // 2
        labels = _components(ok, coarse_r * (ccol + 2) + pair_c)
        lab = labels[rep]
        first = np.arange(ccol - 1) % 2 == parity
        same = (lab[:, :-1] == lab[:, 1:]) & (lab[:, :-1] >= 0)
        open_right[:, first] = (same & usable[:, :-1] & usable[:, 1:])[:, first]
        pair_r = (coarse_r - parity) // 2
        labels = _components(ok, pair_r * (ccol + 2) + coarse_c)
        lab = labels[rep]
        first = np.arange(crow - 1) % 2 == parity
        same = (lab[:-1, :] == lab[1:, :]) & (lab[:-1, :] >= 0)
        open_down[first, :] = (same & usable[:-1, :] & usable[1:, :])[first, :]
    return open_right, open_down


def _primary(usable: np.ndarray, component: np.ndarray, cell_region: np.ndarray) -> np.ndarray:
    """The usable cells in their region's largest component of the graph (the cells located
    to)."""
    primary = np.zeros_like(usable)
    if usable.any():
        pairs, counts = np.unique(
            np.column_stack([cell_region[usable], component[usable]]), axis=0, return_counts=True
        )
        ranked = np.lexsort((-counts, pairs[:, 0]))  # per region, its largest component first
        pairs = pairs[ranked]
        first = np.ones(len(pairs), dtype=bool)
        first[1:] = pairs[1:, 0] != pairs[:-1, 0]
        main = dict(zip(pairs[first, 0].tolist(), pairs[first, 1].tolist(), strict=True))
        lookup = np.vectorize(lambda r: main.get(int(r), -3))
        primary[usable] = component[usable] == lookup(cell_region[usable])
    return primary
