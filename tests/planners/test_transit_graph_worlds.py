"""The transit graph on generated worlds: two or three rooms joined by straight corridors (0.45 to
0.9 m between the walls' faces, 1 to 4 m long), doorways and L-shaped corridors, with furniture
blocks, laid at random on the 5 cm grid (so every alignment of a passage with the graph's coarse
cells turns up).

Properties, for the possible robot centres (fine cells with clearance ≥ radius + clearance):

- (a) every possible centre is located to a cell whose point it reaches by a straight move
  through possible centres, and every two possible centres joined on the fine grid are located
  to cells joined in the graph;
- (b) a goal reachable on the grid is never reported unreachable by ``plan_round`` (one robot,
  to a random possible centre of its region, from a random possible centre or from a place
  nearer a wall than the clearance where the robot's body still fits (robots sweep along
  walls, and a transit starts where the robot stands; its goal then lies in the region of the
  possible centre nearest it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from scipy import ndimage

from planners.deconfliction import TransitRequest, plan_round
from planners.grid import GridMap, clearance
from planners.transit_graph import TransitGraph, build_transit_graph

RES, RADIUS, CLEARANCE, SPEED = 0.05, 0.17, 0.015, 0.25
WORLDS = 60
POINTS_PER_WORLD = 250
ROUNDS_PER_WORLD = 12


@dataclass(frozen=True)
class Rect:
    """Free cells ``[r0, r1) × [c0, c1)`` of the fine grid."""

    r0: int
    c0: int
    r1: int
    c1: int


def _cells(rng: np.random.Generator, lo_m: float, hi_m: float) -> int:
    return int(rng.integers(round(lo_m / RES), round(hi_m / RES) + 1))


def _room_after(rng: np.random.Generator, a: Rect, kind: str) -> tuple[Rect, list[Rect]]:
    """A room to the right of ``a`` and the passage joining them (``kind``: corridor, door or
    ell)."""
    w, h = _cells(rng, 2.0, 4.0), _cells(rng, 2.5, 4.0)
    width = _cells(rng, 0.45, 0.9)
    if kind == "corridor":
        length = _cells(rng, 1.0, 4.0)
        r0 = int(rng.integers(a.r0, a.r1 - width + 1))
        b0 = int(rng.integers(r0 + width - h, r0 + 1))
        b = Rect(b0, a.c1 + length, b0 + h, a.c1 + length + w)
        return b, [Rect(r0, a.c1, r0 + width, b.c0)]
    if kind == "door":
        wall = _cells(rng, 0.1, 0.2)
        b0 = int(rng.integers(a.r0 - h + width + 4, a.r1 - width - 4 + 1))
        b = Rect(b0, a.c1 + wall, b0 + h, a.c1 + wall + w)
        lo, hi = max(a.r0, b.r0), min(a.r1, b.r1)
        r0 = int(rng.integers(lo, hi - width + 1))
        return b, [Rect(r0, a.c1, r0 + width, b.c0)]
    # ell: out of the right wall, then up or down into the next room's floor or ceiling
    across, along = _cells(rng, 0.6, 2.0) + width, _cells(rng, 1.0, 3.0)
    r0 = int(rng.integers(a.r0, a.r1 - width + 1))
    leg = Rect(r0, a.c1, r0 + width, a.c1 + across)
    c0 = a.c1 + across - width
    bc0 = max(a.c1 + 4, c0 - int(rng.integers(0, max(1, w - width))))
    if rng.random() < 0.5:  # up
        up = Rect(r0, c0, r0 + width + along, c0 + width)
        b = Rect(up.r1, bc0, up.r1 + h, max(bc0 + w, up.c1 + 4))
    else:
        down = Rect(r0 - along, c0, r0 + width, c0 + width)
        up = down
        b = Rect(down.r0 - h, bc0, down.r0, max(bc0 + w, down.c1 + 4))
    return b, [leg, up]


def generated_world(seed: int) -> GridMap:
    """Two or three rooms joined left to right by random passages, with furniture blocks."""
    rng = np.random.default_rng(seed)
    rooms = [Rect(0, 0, _cells(rng, 2.5, 4.0), _cells(rng, 2.0, 4.0))]
    passages: list[Rect] = []
    for _ in range(int(rng.integers(1, 3))):
        kind = str(rng.choice(["corridor", "door", "ell"]))
        room, ways = _room_after(rng, rooms[-1], kind)
        rooms.append(room)
        passages += ways
    furniture = []
    for room in rooms:
        for _ in range(int(rng.integers(0, 3))):
            h, w = _cells(rng, 0.3, 1.0), _cells(rng, 0.3, 1.0)
            r0 = int(rng.integers(room.r0, max(room.r0 + 1, room.r1 - h)))
            c0 = int(rng.integers(room.c0, max(room.c0 + 1, room.c1 - w)))
            furniture.append(Rect(r0, c0, r0 + h, c0 + w))
    rects = rooms + passages
    pad = 3
    dr = pad - min(r.r0 for r in rects)
    dc = pad - min(r.c0 for r in rects)
    rows = max(r.r1 for r in rects) + dr + pad
    cols = max(r.c1 for r in rects) + dc + pad
    occ = np.ones((rows, cols), dtype=bool)
    for r in rects:
        occ[r.r0 + dr : r.r1 + dr, r.c0 + dc : r.c1 + dc] = False
    for r in furniture:
        occ[r.r0 + dr : r.r1 + dr, r.c0 + dc : r.c1 + dc] = True
    origin = (float(rng.uniform(-1.0, 1.0)), float(rng.uniform(-1.0, 1.0)))
    return GridMap(occ, np.zeros_like(occ), RES, origin)


def _centres(grid: GridMap) -> tuple[np.ndarray, np.ndarray]:
    """The possible robot centres and their connected regions (4-adjacent, -1 elsewhere)."""
    ok = clearance(grid) >= RADIUS + CLEARANCE - 1e-9
    labels, _ = ndimage.label(ok)
    return ok, labels - 1


def _straight(near: np.ndarray, grid: GridMap, a: np.ndarray, b: np.ndarray) -> bool:
    """Whether the segment a-b runs through possible centres (sampled at a quarter cell), give
    or take the one fine cell of the grid's rasterization: a sample may fall in a cell next to
    a possible centre (``near``; the tip of a sliver of possible centres sees nothing along the
    grid's diagonals), never farther."""
    n = max(2, int(np.ceil(np.hypot(*(b - a)) / (RES / 4))) + 1)
    rc = grid.world_to_cell(a + np.linspace(0.0, 1.0, n)[:, None] * (b - a))
    if not grid.in_bounds(rc).all():
        return False
    return bool(near[rc[:, 0], rc[:, 1]].all())


def _violations(graph: TransitGraph, grid: GridMap, seed: int) -> list[str]:
    ok, region = _centres(grid)
    rng = np.random.default_rng(seed + 1000)
    fine = np.argwhere(ok)
    if len(fine) == 0:
        return []
    fine = fine[rng.permutation(len(fine))[:POINTS_PER_WORLD]]
    xy = grid.cell_to_world(fine)
    cells = graph.locate(xy)
    near = ndimage.binary_dilation(ok, structure=np.ones((3, 3), dtype=bool))
    out = []
    component_of: dict[int, int] = {}
    for p, rc, cell in zip(xy, fine, cells, strict=True):
        where = f"({p[0]:.3f}, {p[1]:.3f})"
        if cell is None:
            out.append(f"{where} is located to no cell")
            continue
        if not _straight(near, grid, p, np.array(graph.point(cell))):
            out.append(f"{where} does not reach the point {graph.point(cell)} of {cell} straight")
        reg, comp = int(region[rc[0], rc[1]]), int(graph.component[cell])
        if component_of.setdefault(reg, comp) != comp:
            out.append(f"{where} is located to another component than the rest of its region")
    return out


def _unreachable(graph: TransitGraph, grid: GridMap, seed: int) -> list[str]:
    ok, region = _centres(grid)
    fits = clearance(grid) >= RADIUS - 1e-9
    nearest = ndimage.distance_transform_edt(~ok, return_distances=False, return_indices=True)
    rng = np.random.default_rng(seed + 2000)
    fine, near_wall = np.argwhere(ok), np.argwhere(fits & ~ok)
    out = []
    for i in range(ROUNDS_PER_WORLD):
        a = fine[rng.integers(len(fine))]
        if i % 2 and len(near_wall):
            a = near_wall[rng.integers(len(near_wall))]
        # a goal in the region of the possible centre nearest the start
        reg = region[nearest[0][a[0], a[1]], nearest[1][a[0], a[1]]]
        same = fine[region[fine[:, 0], fine[:, 1]] == reg]
        b = same[rng.integers(len(same))]
        start, goal = (tuple(map(float, grid.cell_to_world(x))) for x in (a, b))
        plan = plan_round(graph, [TransitRequest("robot", start, goal)], SPEED)
        if plan.status != "success":
            out.append(f"{start} -> {goal}: {plan.status}: {plan.message}")
    return out


@pytest.fixture(scope="module")
def worlds() -> list[tuple[int, GridMap, TransitGraph]]:
    out = []
    for seed in range(WORLDS):
        grid = generated_world(seed)
        out.append((seed, grid, build_transit_graph(grid, RADIUS, CLEARANCE)))
    return out


def test_generated_worlds_have_narrow_passages_of_every_kind(worlds) -> None:
    # the generator's own check: rooms joined through passages a robot fits through
    joined = 0
    for _, grid, _ in worlds:
        ok, region = _centres(grid)
        counts = np.bincount(region[ok])
        joined += counts.max() > 0.9 * counts.sum()
    assert joined >= WORLDS // 2


def test_every_possible_centre_is_located_to_a_cell_it_reaches(worlds) -> None:
    failures = {}
    for seed, grid, graph in worlds:
        bad = _violations(graph, grid, seed)
        if bad:
            failures[seed] = bad[:3] + ([f"... {len(bad)} in all"] if len(bad) > 3 else [])
    assert not failures, failures


def test_no_goal_reachable_on_the_grid_is_reported_unreachable(worlds) -> None:
    failures = {}
    for seed, grid, graph in worlds:
        bad = _unreachable(graph, grid, seed)
        if bad:
            failures[seed] = bad[:2]
    assert not failures, failures
