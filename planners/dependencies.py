"""The order of passage through shared cells of a timed multi-robot plan: execution that
tolerates delay.

Hönig, Kiesel, Tinka, Durham and Ayanian, "Persistent and robust execution of MAPF schedules in
warehouses", IEEE RA-L 2019: a MAPF plan says when each robot is in which cell, but real robots
are late. Its action-dependency graph (ADG) keeps only what makes the plan safe, the order in
which robots pass each cell. Type-1 edges (a robot's own cells in sequence) are kept by driving
the route in order; a type-2 edge says that robot *j* may move into a cell only after robot
*i*, which the plan has there earlier, has moved on into its next cell. A robot that waits until
its type-2 edges are met can never share a cell with another, whatever the delays, and the
robots cannot deadlock: the edges all point forward in the plan's time, so the graph is acyclic.

Here a robot's route is its sequence of distinct cells (waits dropped) with the step at which it
arrives in each; :func:`dependencies` gives each robot the edges into it, and
:func:`blocking` says which of them are not yet met for a given progress. :func:`thin` keeps the
cell points a robot needs to drive through, and :func:`renumber` carries the edges over to them.
"""

from __future__ import annotations

from bisect import bisect_left
from collections import defaultdict
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import networkx as nx
import numpy as np

Cell = tuple[int, int]


@dataclass(frozen=True)
class Route:
    """A robot's cells in the order it drives them (no cell twice in a row), ``arrivals[k]`` the
    plan's step at which it reaches ``cells[k]`` (``arrivals[0] = 0``: where it starts). It
    stays in its last cell."""

    name: str
    cells: tuple[Cell, ...]
    arrivals: tuple[int, ...]

    def __post_init__(self) -> None:
        if not self.cells or len(self.cells) != len(self.arrivals):
            raise ValueError(f"{self.name}: a route needs one arrival step per cell, at least one")
        if any(b <= a for a, b in zip(self.arrivals, self.arrivals[1:], strict=False)):
            raise ValueError(f"{self.name}: arrival steps must increase, got {self.arrivals}")


@dataclass(frozen=True)
class Dependency:
    """The robot may move into its ``index``-th cell only once ``peer`` has reached its own
    ``passed``-th cell (and so left the cell the two share)."""

    index: int
    peer: str
    passed: int


def route_of(name: str, cells_per_step: Sequence[Cell]) -> Route:
    """The route of a plan that gives the robot's cell at every step (waits repeat a cell)."""
    if not cells_per_step:
        raise ValueError(f"{name}: empty plan")
    cells = [tuple(cells_per_step[0])]
    arrivals = [0]
    for step, cell in enumerate(cells_per_step[1:], start=1):
        if tuple(cell) != cells[-1]:
            cells.append(tuple(cell))
            arrivals.append(step)
    return Route(name, tuple(cells), tuple(arrivals))  # type: ignore[arg-type]


def dependencies(routes: Sequence[Route]) -> dict[str, tuple[Dependency, ...]]:
    """The type-2 edges into each robot's route: for each cell it enters, the last earlier
    visit of that cell by each other robot, which must be over before it enters.

    Raises ValueError when the routes are not a conflict-free plan (a robot enters a cell that
    another has not left by then, or that another never leaves)."""
    names = [r.name for r in routes]
    if len(set(names)) != len(names):
        raise ValueError(f"robot names must be distinct, got {names}")
    # every stay: cell -> (arrival, departure or None if for good, robot, index)
    stays: dict[Cell, list[tuple[int, int | None, str, int]]] = defaultdict(list)
    for r in routes:
        for k, (cell, arrive) in enumerate(zip(r.cells, r.arrivals, strict=True)):
            leave = r.arrivals[k + 1] if k + 1 < len(r.cells) else None
            stays[cell].append((arrive, leave, r.name, k))
    out: dict[str, tuple[Dependency, ...]] = {}
    for r in routes:
        edges = []
        for q in range(1, len(r.cells)):
            arrive = r.arrivals[q]
            last: dict[str, tuple[int, int]] = {}
            for a, leave, peer, k in stays[r.cells[q]]:
                if peer == r.name or a > arrive:
                    continue
                if leave is None or leave > arrive:
                    raise ValueError(
                        f"{r.name} enters {r.cells[q]} at step {arrive} while {peer} is "
                        "there: the plan has a conflict"
                    )
                if peer not in last or a > last[peer][0]:
                    last[peer] = (a, k)
            edges += [Dependency(q, peer, k + 1) for peer, (_a, k) in sorted(last.items())]
        out[r.name] = tuple(edges)
    return out


def blocking(
    edges: Sequence[Dependency], index: int, reached: Mapping[str, float]
) -> list[Dependency]:
    """The edges that keep a robot heading for its ``index``-th cell waiting, given the index of
    the cell each peer has reached (a peer missing from ``reached`` has not started)."""
    return [e for e in edges if e.index == index and reached.get(e.peer, -1) < e.passed]


def has_cycle(routes: Sequence[Route], edges: Mapping[str, Sequence[Dependency]]) -> bool:
    """Whether the order of passage is cyclic, as when robots rotate around a block of cells in
    one step (which the MAPF model allows): robots that keep it would wait for each other for
    ever. Nodes are (robot, index of the cell reached); a robot's own cells follow each other,
    and each dependency leads from the peer's ``passed`` to the robot's ``index``."""
    graph = nx.DiGraph()
    for r in routes:
        graph.add_node((r.name, 0))
        graph.add_edges_from(((r.name, k - 1), (r.name, k)) for k in range(1, len(r.cells)))
    for name, deps in edges.items():
        graph.add_edges_from(((d.peer, d.passed), (name, d.index)) for d in deps)
    return not nx.is_directed_acyclic_graph(graph)


def thin(
    points: np.ndarray, keep: set[int], clear: Callable[[np.ndarray, np.ndarray], bool]
) -> list[int]:
    """The indices of a route's cell points worth driving through: the ends, ``keep``, and
    those that line of sight needs (greedy string pulling between kept points; ``clear(a, b)``
    says whether a robot centre may move straight from a to b). The staircase of a 4-connected
    route becomes straight runs, which the robot drives without a turn in place at every cell."""
    n = len(points)
    fixed = sorted({0, n - 1, *(k for k in keep if 0 <= k < n)})
    out = [0]
    for stop in fixed[1:]:
        i = out[-1]
        while i < stop:
            j = stop
            while j > i + 1 and not clear(points[i], points[j]):
                j -= 1
            out.append(j)
            i = j
    return out


def renumber(
    edges: Mapping[str, Sequence[Dependency]], kept: Mapping[str, Sequence[int]]
) -> dict[str, tuple[Dependency, ...]]:
    """The dependencies in the numbering of the thinned routes (``kept[name]``, from
    :func:`thin`): a robot holds before the first kept point at or after the cell it waits to
    enter, at a kept point before it; a peer has passed once it has reached its first kept point
    at or after the cell. Both err on the safe side, and are exact where the cells are kept."""

    def at_or_after(name: str, k: int) -> int:
        return bisect_left(kept[name], k)

    out = {}
    for name, deps in edges.items():
        rows = {}
        for d in deps:
            key = (at_or_after(name, d.index), d.peer)
            rows[key] = max(rows.get(key, -1), at_or_after(d.peer, d.passed))
        out[name] = tuple(Dependency(i, peer, p) for (i, peer), p in sorted(rows.items()))
    return out
