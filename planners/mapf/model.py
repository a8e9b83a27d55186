"""The MAPF model: instances, solutions, results, and the feasibility check run before search.

Model (Stern et al., "Multi-Agent Pathfinding: Definitions, Variants, and Benchmarks", SoCS 2019):
a 4-connected grid, unit-time moves and waits; vertex conflicts (two agents in one cell at one
time) and swap conflicts (two agents exchanging cells in one step) are forbidden, following and
rotation are allowed. An agent's cost is the time it reaches its goal for the last time; it then
stays there, so an agent passing through a parked agent's goal is a (target) vertex conflict.
SOC is the sum of the costs, makespan their maximum.

Cells are ``(row, col)`` tuples; row 0 is the first row of the array (for MovingAI files that is
the top line, ``y = 0``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

Cell = tuple[int, int]
Path = tuple[Cell, ...]

# "failed": an incomplete solver (prioritized planning) gave up after its allowed restarts.
STATUSES = ("success", "timeout", "infeasible", "failed")


class InfeasibleInstanceError(ValueError):
    """The instance has no solution for a reason visible before search (blocked or shared cells)."""


class SearchTimeout(Exception):
    """Raised inside solvers when the deadline passes; ``solve`` turns it into status timeout."""


@dataclass(frozen=True, eq=False)
class MapfInstance:
    """A grid (``free[r, c]`` True where passable) and one start and goal cell per agent."""

    free: np.ndarray
    starts: tuple[Cell, ...]
    goals: tuple[Cell, ...]
    names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        free = np.asarray(self.free, dtype=bool)
        if free.ndim != 2:
            raise ValueError(f"free must be a 2D array, got shape {free.shape}")
        object.__setattr__(self, "free", free)
        object.__setattr__(self, "starts", tuple((int(r), int(c)) for r, c in self.starts))
        object.__setattr__(self, "goals", tuple((int(r), int(c)) for r, c in self.goals))
        if len(self.starts) != len(self.goals):
            raise ValueError(f"{len(self.starts)} starts but {len(self.goals)} goals")
        names = self.names or tuple(f"agent{i}" for i in range(len(self.starts)))
        if len(names) != len(self.starts):
            raise ValueError(f"{len(names)} names for {len(self.starts)} agents")
        object.__setattr__(self, "names", tuple(names))

    @property
    def num_agents(self) -> int:
        return len(self.starts)

    @property
    def shape(self) -> tuple[int, int]:
        return self.free.shape  # type: ignore[return-value]

    def first(self, k: int) -> MapfInstance:
        """The instance with only the first ``k`` agents (MovingAI convention for scenarios)."""
        if not 0 < k <= self.num_agents:
            raise ValueError(f"k={k} must be in 1..{self.num_agents}")
        return MapfInstance(self.free, self.starts[:k], self.goals[:k], self.names[:k])


@dataclass(frozen=True)
class MapfSolution:
    """One path per agent, ``paths[i][t]`` the cell at time t; after its end the agent stays put."""

    paths: tuple[Path, ...]

    @property
    def costs(self) -> tuple[int, ...]:
        return tuple(path_cost(p) for p in self.paths)

    @property
    def soc(self) -> int:
        return sum(self.costs)

    @property
    def makespan(self) -> int:
        return max(self.costs, default=0)


@dataclass(frozen=True)
class MapfResult:
    """What a solver returns. ``solution`` is None unless ``status == "success"``.

    ``lower_bound`` is a proven lower bound on the optimal SOC where the solver has one (CBS:
    equal to the SOC on success; ECBS: the focal bound, SOC ≤ w · lower_bound).
    """

    status: str
    solver: str
    solution: MapfSolution | None
    runtime_s: float
    expanded_high: int = 0
    expanded_low: int = 0
    lower_bound: int | None = None
    message: str = ""
    details: dict[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"status must be one of {STATUSES}, got {self.status!r}")

    @property
    def soc(self) -> int | None:
        return None if self.solution is None else self.solution.soc

    @property
    def makespan(self) -> int | None:
        return None if self.solution is None else self.solution.makespan

    @property
    def expanded(self) -> int:
        return self.expanded_high + self.expanded_low


def path_cost(path: Path | list[int] | tuple[int, ...]) -> int:
    """Arrival time of the last arrival at the final cell (trailing waits there are free)."""
    t = len(path) - 1
    while t > 0 and path[t - 1] == path[-1]:
        t -= 1
    return t


def check_instance(instance: MapfInstance) -> None:
    """Reject instances that have no solution for a visible reason; raises InfeasibleInstanceError.

    Checks, per agent: start and goal inside the grid and free, no start or goal shared with
    another agent, start and goal in the same 4-connected component.
    """
    rows, cols = instance.shape
    problems: list[str] = []
    for i, name in enumerate(instance.names):
        for what, (r, c) in (("start", instance.starts[i]), ("goal", instance.goals[i])):
            if not (0 <= r < rows and 0 <= c < cols):
                problems.append(
                    f"{name}: {what} (row {r}, col {c}) is outside the {rows}x{cols} grid"
                )
            elif not instance.free[r, c]:
                problems.append(f"{name}: {what} (row {r}, col {c}) is an obstacle")
    for what, cells in (("start", instance.starts), ("goal", instance.goals)):
        owner: dict[Cell, str] = {}
        for name, cell in zip(instance.names, cells, strict=False):
            if cell in owner:
                problems.append(
                    f"{owner[cell]} and {name} share the {what} (row {cell[0]}, col {cell[1]})"
                )
            owner.setdefault(cell, name)
    if problems:
        raise InfeasibleInstanceError("; ".join(problems))
    labels, _ = ndimage.label(instance.free)
    for name, (sr, sc), (gr, gc) in zip(
        instance.names, instance.starts, instance.goals, strict=False
    ):
        if labels[sr, sc] != labels[gr, gc]:
            problems.append(
                f"{name}: goal (row {gr}, col {gc}) is unreachable from start (row {sr}, col {sc})"
            )
    if problems:
        raise InfeasibleInstanceError("; ".join(problems))
