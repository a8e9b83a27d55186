"""The transit graph: coarse cells a robot occupies alone, a narrow passage as a chain of single
cells, no move through a wall, and the corridor world's two rooms joined through its corridor."""

from __future__ import annotations

import numpy as np
from scipy.spatial.distance import pdist, squareform

from fleet.config import resolve_world
from fleet.world import load_world
from planners.grid import GridMap
from planners.transit_graph import build_transit_graph

RES = 0.05
RADIUS, CLEARANCE = 0.17, 0.015


def _two_rooms(door: bool) -> GridMap:
    """Two 2 x 2.4 m rooms, x 0.1-2.1 and 3.3-5.3, joined (``door``) by a passage 0.5 m wide
    (y 1.2-1.7) and 1.2 m long, or split by a wall one fine cell thick at x 2.4 (no door)."""
    rows, cols = 52, 108
    occ = np.zeros((rows, cols), dtype=bool)
    occ[:2, :] = occ[-2:, :] = True
    occ[:, :2] = occ[:, -2:] = True
    if door:
        occ[:, 42:66] = True
        occ[24:34, 42:66] = False
    else:
        occ[:, 48] = True
    return GridMap(occ, np.zeros_like(occ), RES, (0.0, 0.0))


def test_a_narrow_passage_is_a_chain_of_single_cells() -> None:
    graph = build_transit_graph(_two_rooms(door=True), RADIUS, CLEARANCE)
    assert graph.cell_size == 0.4
    # coarse columns lying wholly inside the passage (x 2.1-3.3): 6 and 7
    passage = graph.usable[:, 6:8]
    assert passage.sum(axis=0).tolist() == [1, 1]
    (row,) = np.nonzero(passage[:, 0])
    r = int(row[0])
    assert graph.usable[r, 6] and graph.usable[r, 7]
    assert graph.joined((r, 5), (r, 6)) and graph.joined((r, 6), (r, 7))
    assert graph.joined((r, 7), (r, 8))
    assert graph.degree()[r, 6:8].tolist() == [2, 2]
    # the passage's points lie on its centre line, between the walls
    for c in (6, 7):
        x, y = graph.point((r, c))
        assert 1.2 + RADIUS <= y <= 1.7 - RADIUS and 2.1 < x < 3.3
    # the two rooms are one component, joined only through the passage
    left, right = graph.locate(np.array([[1.0, 1.0], [4.5, 2.0]]))
    assert graph.component[left] == graph.component[right]
    cut = graph.open_right.copy()
    cut[r, 6] = False
    assert graph.open_right.sum() - cut.sum() == 1


def test_cells_split_by_a_wall_are_not_joined() -> None:
    # 0.8 m cells: the wall runs along the border of coarse columns 2 and 3, whose points
    # (near their centres) are 0.8 m apart
    graph = build_transit_graph(_two_rooms(door=False), RADIUS, CLEARANCE, cell_size=0.8)
    left, right = graph.locate(np.array([[1.0, 1.2], [3.0, 1.2]]))
    assert graph.component[left] != graph.component[right]
    # cells on both sides of the wall are usable and touch, yet no move crosses it
    touching = graph.usable[:, 2] & graph.usable[:, 3]
    assert touching.sum() >= 2
    assert not graph.open_right[:, 2].any()
    assert graph.open_right[:, 1].any() and graph.open_right[:, 3].any()


def test_robots_at_the_points_of_different_cells_never_overlap() -> None:
    world = load_world(resolve_world("home"))
    graph = build_transit_graph(world.grid(RES), RADIUS, CLEARANCE)
    points = graph.points[graph.usable]
    assert len(points) > 100
    # but for the few bridges (cells joining a region's parts), whose too-near neighbours
    # planners.deconfliction keeps free while a robot stands in them
    assert 0 < graph.bridge.sum() <= 8
    flat = np.flatnonzero(graph.usable)
    close = np.argwhere(squareform(pdist(points)) < 2 * (RADIUS + CLEARANCE) - 1e-9)
    close = {tuple(sorted((int(flat[i]), int(flat[j])))) for i, j in close if i != j}
    assert close == {tuple(sorted(p)) for p in graph.crowded.tolist()}
    bridges = set(np.flatnonzero(graph.bridge).tolist())
    assert all(a in bridges or b in bridges for a, b in close)
    clearance = world.clearance(points)
    assert clearance.min() >= RADIUS


def test_the_corridor_world_joins_its_two_rooms_through_the_corridor() -> None:
    world = load_world(resolve_world("corridor"))
    graph = build_transit_graph(world.grid(RES), RADIUS, CLEARANCE)
    left, right = graph.locate(np.array([[1.5, 1.5], [6.5, 1.0]]))
    assert graph.component[left] == graph.component[right]
    # the corridor (x 3.05-4.95, y 1.2-1.7) holds one row of cells, a chain
    cells = np.argwhere(graph.usable)
    pts = graph.points[cells[:, 0], cells[:, 1]]
    inside = (pts[:, 0] > 3.05) & (pts[:, 0] < 4.95) & (pts[:, 1] > 1.2) & (pts[:, 1] < 1.7)
    corridor = cells[inside]
    assert len(corridor) >= 4
    assert len(set(corridor[:, 0].tolist())) == 1
    deg = graph.degree()
    assert all(deg[r, c] == 2 for r, c in corridor)
    # cutting one corridor edge splits the rooms: the corridor is the only way
    r, c = corridor[len(corridor) // 2]
    open_right = graph.open_right.copy()
    open_right[r, c] = False
    from planners.mapf.grid_graph import GridGraph

    cut = GridGraph(graph.usable, open_right, graph.open_down)
    assert cut.distances(cut.cell(right))[cut.cell(left)] >= 1 << 30


def test_points_of_one_region_locate_to_one_component() -> None:
    world = load_world(resolve_world("home"))
    grid = world.grid(RES)
    graph = build_transit_graph(grid, RADIUS, CLEARANCE)
    # home's floor is one component: cells whose way out ran diagonally or through a cell
    # dropped for spacing are joined by moved points and bridges
    region = graph.fine_region[: grid.shape[0], : grid.shape[1]]
    main = np.bincount(region[region >= 0]).argmax()
    assert len(set(graph.component[graph.cell_region == main].tolist())) == 1
    region = graph.fine_region[: grid.shape[0], : grid.shape[1]]
    main = np.bincount(region[region >= 0]).argmax()
    fine = np.argwhere(region == main)[::7]
    cells = graph.locate(grid.cell_to_world(fine))
    assert all(c is not None for c in cells)
    assert len({int(graph.component[c]) for c in cells}) == 1


def test_goals_in_a_corridor_whose_centres_straddle_a_cell_border_are_reachable() -> None:
    # corridor_wide: 0.6 m between the faces (y 1.7-2.3), robot centres at y 1.885-2.115 across
    # the cells' border at y 1.95; the graph had the corridor's goals in a component of their
    # own, and a transit to (7.76, 2.09) "cannot be reached" even from the rooms
    world = load_world(resolve_world("corridor_wide"))
    graph = build_transit_graph(world.grid(RES), RADIUS, CLEARANCE)
    from planners.deconfliction import TransitRequest, plan_round

    for start in [(6.03, 2.05), (1.0, 1.0), (11.0, 3.0), (6.03, 1.87)]:
        plan = plan_round(graph, [TransitRequest("r", start, (7.76, 2.09))], 0.25)
        assert plan.status == "success", plan.message
    rooms = graph.locate(np.array([[1.0, 1.0], [11.0, 3.0], [7.5, 2.0]]))
    assert len({int(graph.component[c]) for c in rooms}) == 1
