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
  ``2 · (radius + clearance)`` (a narrow passage whose centre line runs along a cell border, a
  cell cut by the edge of a piece of furniture or a doorway's jamb), the cells are taken in
  order of how near their points lie to their own centres (ties: lower index): each keeps its
  point if it stands clear of the points kept so far, else moves it to the possible centre of
  its cell nearest the centre that does, else is dropped. So robots standing at the points of
  different cells never overlap, a one-robot-wide corridor is one chain of cells, not two side
  by side, and the cells along walls and round furniture, which a plain drop lost, are kept.
- **Adjacency.** Two 4-adjacent usable cells are joined when a robot centre can move from one
  point to the other through possible centres inside the two cells alone (a 4-connected path of
  fine cells in their union). A corridor one robot wide is thus a chain of single cells, each
  joined only to the next.
- **Bridges.** A region of possible centres (4-connected fine cells) must be one component of
  the graph. Where a passage narrower than a cell bends, or runs along a cell border, its
  cells' points can step diagonally, and no point of the cell between them stands clear of
  both: the region falls apart. An unused cell 4-adjacent to two components of one region then
  becomes a bridge, its point the possible centre of its cell farthest from the points round
  it; failing such a cell, two unused cells side by side, each next to another component (a
  passage one fine cell wide at a bend); up to ``BRIDGE_ROUNDS`` rounds. A bridge's point
  stands nearer its neighbours' than the spacing: ``crowded`` lists those pairs, and
  prioritized planning (``planners.deconfliction``) reserves them together, so no two robots
  stand in a crowded pair at one step (the joint CBS/ECBS fallback does not know them). On the
  generated worlds of ``tests/planners/test_transit_graph_worlds.py`` (and on 800 of them)
  every region is one component after bridging; home has 4 bridges, the warehouse of ``fleet bench
  deconfliction`` 2.
- **Locating.** Each possible centre is located to the cell, of its region's largest
  component (all of it, once bridged), nearest it along the floor: a geodesic Voronoi
  partition of the possible centres round the cells' points, by one multi-source Dijkstra on
  the fine grid (``scipy.sparse.csgraph.dijkstra(min_only=True)``), so no point is located
  through a wall to a cell it cannot reach, as the nearest cell in a straight line could be.
  Where that cell's point is out of sight (round the end of a wall), the nearest of its
  ``SIGHT_CANDIDATES`` nearest cells whose point it sees instead: a robot drives from where it
  stands to its first cell's point, and from its last one to its goal, in a straight line. A
  point that is not a possible centre (a robot nearer a wall than the clearance, after an edge
  pass or by the error of its pose) is located as the possible centre nearest it (Euclidean
  distance transform): the rule that called such a start "off every region" and located it to
  the nearest usable cell of any region made the coordinator report reachable goals as
  unreachable. Locating to the nearest cell through free fine cells was chosen over cells on
  a corridor's medial axis because the graph must stay a 4-adjacent coarse grid for the MAPF
  solvers (``planners.mapf``), whose cells a medial axis does not follow, and it settles the
  points between cells everywhere, not only in corridors.

Every step is numpy / scipy over the whole grid (connected components and Dijkstra by
``scipy.sparse.csgraph``), built once per floor plan; only the cells whose points crowd each
other, the bridges and the possible centres out of sight of their cell are taken one by one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from planners.grid import GridMap, clearance
from planners.mapf.grid_graph import GridGraph

Cell = tuple[int, int]

# rounds of bridging (``_bridge``): each joins parts of a region across one cell
BRIDGE_ROUNDS = 4
# a possible centre out of sight of its geodesically nearest cell's point takes the nearest in
# sight of this many cells nearest it
SIGHT_CANDIDATES = 12


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
    owner: np.ndarray  # per fine cell, the flat index of the cell it is located to; -1: none
    bridge: np.ndarray  # cells added to join a region's parts, nearer their neighbours' points
    crowded: np.ndarray  # (m, 2) flat indices of the cells whose points stand nearer than spacing

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
        """For each world point, up to ``k`` usable cells: the cell it is located to (``owner``,
        see the module), then the other located-to cells of its region, nearest first; all usable
        cells, nearest first, for a point no cell is located from."""
        xy = np.atleast_2d(np.asarray(xy, dtype=float))
        cells = np.argwhere(self.usable)
        if len(cells) == 0:
            return [[] for _ in xy]
        pts = self.points[cells[:, 0], cells[:, 1]]
        regions = np.where(
            self.primary[cells[:, 0], cells[:, 1]], self.cell_region[cells[:, 0], cells[:, 1]], -2
        )
        rows, cols = self.owner.shape
        fine = np.floor((xy[:, ::-1] - np.array(self.origin)[::-1]) / self.fine_resolution)
        fine = np.clip(fine, 0, [rows - 1, cols - 1]).astype(np.int64)
        owner = self.owner[fine[:, 0], fine[:, 1]]
        flat = cells[:, 0] * self.shape[1] + cells[:, 1]
        out: list[list[Cell]] = []
        for p, own in zip(xy, owner.tolist(), strict=True):
            if own < 0:
                pool = np.arange(len(cells))
            else:
                pool = np.nonzero((regions == self.cell_region.flat[own]) & (flat != own))[0]
            d = np.hypot(*(pts[pool] - p).T)
            first = [divmod(own, self.shape[1])] if own >= 0 else []
            nearest = pool[np.argsort(d, kind="stable")[: k - len(first)]]
            out.append(first + [(int(r), int(c)) for r, c in cells[nearest]])
        return out

    def crowding(self) -> dict[int, tuple[int, ...]]:
        """For each cell (flat index, as ``graph`` numbers them) whose point stands nearer than
        ``2 · (radius + clearance)`` to others' (a bridge and its neighbours), those cells."""
        out: dict[int, list[int]] = {}
        for a, b in self.crowded.tolist():
            out.setdefault(a, []).append(b)
            out.setdefault(b, []).append(a)
        return {cell: tuple(sorted(others)) for cell, others in out.items()}

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

    # each coarse cell's point: the possible centre nearest its geometric centre, moved within
    # its cell or dropped where it comes too near another's (``_spaced``)
    off = (np.arange(k) + 0.5) - k / 2.0
    d2 = (off[:, None] ** 2 + off[None, :] ** 2).ravel()
    blocks = ok.reshape(crow, k, ccol, k).transpose(0, 2, 1, 3).reshape(crow, ccol, k * k)
    score = np.where(blocks, d2[None, None, :], np.inf)
    best = np.argmin(score, axis=2)
    usable = blocks.any(axis=2)
    fr = np.arange(crow)[:, None] * k + best // k
    fc = np.arange(ccol)[None, :] * k + best % k
    usable, fr, fc = _spaced(ok, usable, fr, fc, np.min(score, axis=2), spacing / res, k)
    fine_region = _components(ok, np.zeros_like(ok, dtype=np.int64)).reshape(ok.shape)
    bridge = np.zeros_like(usable)
    for round_ in range(BRIDGE_ROUNDS + 1):
        rep = (fr * (ccol * k) + fc).astype(np.int64)  # flat fine index of each cell's point
        open_right, open_down = _openings(ok, usable, rep, k)
        component = _graph_components(usable, open_right, open_down)
        if round_ == BRIDGE_ROUNDS:
            break
        added = _bridge(ok, blocks.any(axis=2), usable, fr, fc, component, fine_region, k)
        if not added.any():
            break
        bridge |= added
    x = grid.origin[0] + (fc + 0.5) * res
    y = grid.origin[1] + (fr + 0.5) * res
    points = np.full((crow, ccol, 2), np.nan)
    points[usable, 0] = x[usable]
    points[usable, 1] = y[usable]
    graph = GridGraph(usable, open_right, open_down)
    cell_region = np.where(usable, fine_region.ravel()[rep], -1)
    primary = _primary(usable, component, cell_region)
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
        primary=primary,
        owner=_owners(ok, rep[primary], np.flatnonzero(primary), res),
        bridge=bridge,
        crowded=_crowded(points, usable, spacing),
    )


def _spaced(
    ok: np.ndarray,
    usable: np.ndarray,
    fr: np.ndarray,
    fc: np.ndarray,
    score: np.ndarray,
    spacing: float,
    k: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The usable cells and their points (fine row ``fr``, column ``fc``) at least ``spacing``
    fine cells apart. Cells whose points stand clear of every other keep them. The others are
    taken in order of how near their points lie to their own centres (``score``; ties: lower
    index): a cell keeps its point if it is clear of the points kept so far, else takes the
    possible centre (``ok``) of its own ``k`` × ``k`` block nearest its centre that is, else is
    dropped. Moving a point instead of dropping its cell keeps the cells round a piece of
    furniture, a doorway's jamb or a corridor's bend, whose nearest-to-centre points crowd each
    other, joined to the rest."""
    cells = np.argwhere(usable)
    pts = np.column_stack([fc[usable], fr[usable]]).astype(float)
    pairs = cKDTree(pts).query_pairs(spacing - 1e-9, output_type="ndarray") if len(pts) else []
    if not len(pairs):
        return usable, fr, fc
    crowded = np.unique(pairs.ravel())
    rank = np.lexsort((crowded, score[usable][crowded]))
    kept, fr, fc = usable.copy(), fr.copy(), fc.copy()
    kept[cells[crowded, 0], cells[crowded, 1]] = False
    reach = math.ceil(spacing / k)  # points nearer than spacing lie this many cells apart at most
    off = np.arange(k)
    centre = (k - 1) / 2.0
    for i in crowded[rank].tolist():
        r, c = cells[i]
        r0, c0 = max(r - reach, 0), max(c - reach, 0)
        near = kept[r0 : r + reach + 1, c0 : c + reach + 1]
        others = np.column_stack(
            [
                fr[r0 : r + reach + 1, c0 : c + reach + 1][near],
                fc[r0 : r + reach + 1, c0 : c + reach + 1][near],
            ]
        )
        rr, cc = np.nonzero(ok[r * k : (r + 1) * k, c * k : (c + 1) * k])
        order = np.argsort((off[rr] - centre) ** 2 + (off[cc] - centre) ** 2, kind="stable")
        cand = np.column_stack([rr[order] + r * k, cc[order] + c * k])
        if len(others):
            gap = np.hypot(*(cand[:, None, :] - others[None, :, :]).transpose(2, 0, 1)).min(axis=1)
            cand = cand[gap >= spacing - 1e-9]
        if len(cand):
            kept[r, c] = True
            fr[r, c], fc[r, c] = cand[0]
    return kept, fr, fc


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


def _crowded(points: np.ndarray, usable: np.ndarray, spacing: float) -> np.ndarray:
    """The pairs of usable cells (flat indices) whose points stand nearer than ``spacing``."""
    flat = np.flatnonzero(usable)
    if len(flat) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    pairs = cKDTree(points[usable]).query_pairs(spacing - 1e-9, output_type="ndarray")
    return flat[pairs].reshape(-1, 2)


def _graph_components(
    usable: np.ndarray, open_right: np.ndarray, open_down: np.ndarray
) -> np.ndarray:
    """The connected component of each usable cell of the graph (-1 elsewhere)."""
    crow, ccol = usable.shape
    cidx = np.arange(crow * ccol).reshape(crow, ccol)
    a = np.concatenate([cidx[:, :-1][open_right], cidx[:-1, :][open_down]])
    b = np.concatenate([cidx[:, 1:][open_right], cidx[1:, :][open_down]])
    n = crow * ccol
    _, comp = connected_components(
        coo_matrix((np.ones(a.size), (a, b)), shape=(n, n)).tocsr(), directed=False
    )
    return np.where(usable.ravel(), comp, -1).reshape(usable.shape)


def _bridge(
    ok: np.ndarray,
    has_centre: np.ndarray,
    usable: np.ndarray,
    fr: np.ndarray,
    fc: np.ndarray,
    component: np.ndarray,
    fine_region: np.ndarray,
    k: int,
) -> np.ndarray:
    """Cells added (in place: ``usable``, ``fr``, ``fc``) where a region of possible centres falls
    apart in the graph: an unused cell holding possible centres of a region, 4-adjacent to cells
    of two or more of that region's components, or failing those, two 4-adjacent unused cells
    each next to another of its components, get the points of their blocks that stand farthest
    from the points round them. Such a step happens where a passage narrower than a cell bends
    or runs along a cell border: its cells' points step diagonally, and no point of the cell
    between them stands clear of both. A bridge's point is nearer its neighbours' than
    ``2 · (radius + clearance)``: ``planners.deconfliction`` keeps a robot out of a bridge's
    neighbours while another is in it. Single bridges are not 4-adjacent to each other within
    one round; returns the cells added."""
    crow, ccol = usable.shape
    region = np.where(usable, fine_region.ravel()[(fr * (ccol * k) + fc)], -1)
    pad_c = np.pad(component, 1, constant_values=-1)
    pad_r = np.pad(region, 1, constant_values=-1)
    sides = [(0, 1), (2, 1), (1, 0), (1, 2)]
    comps = np.stack([pad_c[dr : dr + crow, dc : dc + ccol] for dr, dc in sides])
    regs = np.stack([pad_r[dr : dr + crow, dc : dc + ccol] for dr, dc in sides])
    # two sides of one region in different components
    split = np.zeros(usable.shape, dtype=bool)
    for i in range(4):
        for j in range(i + 1, 4):
            split |= (regs[i] >= 0) & (regs[i] == regs[j]) & (comps[i] != comps[j])
    unused = has_centre & ~usable
    added = np.zeros_like(usable)
    for r, c in np.argwhere(split & unused).tolist():
        if added[max(r - 1, 0) : r + 2, c].any() or added[r, max(c - 1, 0) : c + 2].any():
            continue
        wanted = regs[:, r, c][regs[:, r, c] >= 0]
        _place(ok, usable, fr, fc, fine_region, k, r, c, wanted, added)
    if added.any():
        return added
    # two unused cells side by side, each next to another component of one region
    side = np.argmax(np.where(regs >= 0, comps, -1), axis=0)
    rep_c = np.take_along_axis(comps, side[None], axis=0)[0]
    rep_r = np.take_along_axis(regs, side[None], axis=0)[0]
    rep_c = np.where(unused & (rep_r >= 0), rep_c, -1)
    pairs = []
    for dr, dc in ((0, 1), (1, 0)):
        a_c, b_c = rep_c[: crow - dr, : ccol - dc], rep_c[dr:, dc:]
        a_r, b_r = rep_r[: crow - dr, : ccol - dc], rep_r[dr:, dc:]
        hit = (a_c >= 0) & (b_c >= 0) & (a_c != b_c) & (a_r == b_r)
        pairs += [(r, c, r + dr, c + dc) for r, c in np.argwhere(hit).tolist()]
    for r0, c0, r1, c1 in pairs:
        if added[max(r0 - 1, 0) : r1 + 2, max(c0 - 1, 0) : c1 + 2].any():
            continue
        wanted = np.array([rep_r[r0, c0]])
        for r, c in ((r0, c0), (r1, c1)):
            _place(ok, usable, fr, fc, fine_region, k, r, c, wanted, added)
    return added


def _place(
    ok: np.ndarray,
    usable: np.ndarray,
    fr: np.ndarray,
    fc: np.ndarray,
    fine_region: np.ndarray,
    k: int,
    r: int,
    c: int,
    regions: np.ndarray,
    added: np.ndarray,
) -> None:
    """Make coarse cell (r, c) a bridge (in place), its point the possible centre of its block in
    one of ``regions`` farthest from the points of the cells round it; nothing if it has
    none."""
    rows = slice(max(r - 1, 0), r + 2)
    cols = slice(max(c - 1, 0), c + 2)
    near = usable[rows, cols]
    others = np.column_stack([fr[rows, cols][near], fc[rows, cols][near]])
    rr, cc = np.nonzero(ok[r * k : (r + 1) * k, c * k : (c + 1) * k])
    rr, cc = rr + r * k, cc + c * k
    mine = np.isin(fine_region[rr, cc], regions)
    if not mine.any():
        return
    rr, cc = rr[mine], cc[mine]
    gap = np.hypot(rr[:, None] - others[None, :, 0], cc[:, None] - others[None, :, 1])
    best = int(np.argmax(gap.min(axis=1))) if len(others) else 0
    usable[r, c], added[r, c] = True, True
    fr[r, c], fc[r, c] = rr[best], cc[best]


def _owners(ok: np.ndarray, sources: np.ndarray, cells: np.ndarray, res: float) -> np.ndarray:
    """Per fine cell, the flat index of the cell (of ``cells``, whose points are the fine cells
    ``sources``) nearest it along a way through possible centres (``ok``): a geodesic Voronoi
    partition of the possible centres, by one multi-source Dijkstra on the fine grid (8-adjacent,
    a diagonal step only between two open sides, so it never slips between regions). A fine cell
    outside ``ok`` (a robot nearer a wall than its clearance, or a pose a little off) takes the
    owner of the nearest possible centre (Euclidean distance transform). -1 where no cell is
    reachable."""
    rows, cols = ok.shape
    n = rows * cols
    idx = np.arange(n).reshape(rows, cols)
    a_parts, b_parts, w_parts = [], [], []
    for (dr, dc), w in (
        ((0, 1), 1.0),
        ((1, 0), 1.0),
        ((1, 1), math.sqrt(2)),
        ((1, -1), math.sqrt(2)),
    ):
        lo_c, hi_c = max(0, -dc), cols - max(0, dc)
        src = ok[: rows - dr, lo_c:hi_c]
        dst = ok[dr:, lo_c + dc : hi_c + dc]
        both = src & dst
        if dr and dc:
            both &= ok[: rows - dr, lo_c + dc : hi_c + dc] & ok[dr:, lo_c:hi_c]
        a_parts.append(idx[: rows - dr, lo_c:hi_c][both])
        b_parts.append(idx[dr:, lo_c + dc : hi_c + dc][both])
        w_parts.append(np.full(int(both.sum()), w * res))
    a, b, w = np.concatenate(a_parts), np.concatenate(b_parts), np.concatenate(w_parts)
    owner = np.full(n, -1, dtype=np.int64)
    if len(sources):
        graph = coo_matrix((w, (a, b)), shape=(n, n)).tocsr()
        _, _, nearest = dijkstra(
            graph, directed=False, indices=sources, min_only=True, return_predecessors=True
        )
        cell_of = np.full(n, -1, dtype=np.int64)
        cell_of[sources] = cells
        reached = nearest >= 0
        owner[reached] = cell_of[nearest[reached]]
    owner = owner.reshape(rows, cols)
    _in_sight(ok, owner, sources, cells)
    if ok.any() and not ok.all():
        near = ndimage.distance_transform_edt(~ok, return_distances=False, return_indices=True)
        owner = owner[near[0], near[1]]
    return owner


def _sees(ok: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether the segments between the centres of fine cells ``a`` and ``b`` ((n, 2) rows,
    columns) run through ``ok`` cells only (sampled every quarter cell; a segment through the
    corner of a blocked cell is not clear). Segments are taken in groups of like length."""
    seen = np.ones(len(a), dtype=bool)
    if len(a) == 0:
        return seen
    length = np.hypot(*(b - a).T)
    group = np.ceil(np.log2(np.maximum(length, 1.0))).astype(np.int64)
    for g in np.unique(group).tolist():
        pick = np.flatnonzero(group == g)
        f = np.linspace(0.0, 1.0, 4 * 2**g + 1)
        along = a[pick, None, :] + 0.5 + f[None, :, None] * (b - a)[pick, None, :]
        for dr, dc in ((-1e-6, -1e-6), (-1e-6, 1e-6), (1e-6, -1e-6), (1e-6, 1e-6)):
            at = np.floor(along + np.array([dr, dc])).astype(np.int64)
            np.clip(at, 0, np.array(ok.shape) - 1, out=at)
            seen[pick] &= ok[at[..., 0], at[..., 1]].all(axis=1)
    return seen


def _in_sight(ok: np.ndarray, owner: np.ndarray, sources: np.ndarray, cells: np.ndarray) -> None:
    """Where a possible centre does not see the point of the cell nearest it along the floor
    (round the end of a wall, a geodesic neighbour can lie out of sight), the nearest cell whose
    point it sees straight, of its ``SIGHT_CANDIDATES`` nearest cells; in place."""
    if not len(sources):
        return
    cols = ok.shape[1]
    point_of = np.full(int(cells.max()) + 1, -1, dtype=np.int64)
    point_of[cells] = sources
    fine = np.argwhere(ok & (owner >= 0))
    own = point_of[owner[fine[:, 0], fine[:, 1]]]
    target = np.column_stack(np.divmod(own, cols))
    # a possible centre within the disc of possible centres round its cell's point sees it
    room = ndimage.distance_transform_edt(ok)[target[:, 0], target[:, 1]]
    doubt = np.hypot(*(fine - target).T) + 1.5 > room
    fine, target = fine[doubt], target[doubt]
    blind = fine[~_sees(ok, fine.astype(float), target.astype(float))]
    if not len(blind):
        return
    pts = np.column_stack(np.divmod(sources, cols)).astype(float)
    k = min(SIGHT_CANDIDATES, len(pts))
    _, near = cKDTree(pts).query(blind.astype(float), k=k)
    near = near.reshape(len(blind), k)
    seen = _sees(ok, np.repeat(blind, k, axis=0).astype(float), pts[near.ravel()])
    seen = seen.reshape(len(blind), k)
    fixed = seen.any(axis=1)
    first = near[np.arange(len(blind)), np.argmax(seen, axis=1)]
    owner[blind[fixed, 0], blind[fixed, 1]] = cells[first[fixed]]


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
