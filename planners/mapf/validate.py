"""An independent check of any MAPF solution, and its SOC and makespan recomputed.

It shares no code with the solvers: it walks the paths cell by cell (the slow, obvious way) and
checks bounds, obstacles, unit moves (and, for graphs with closed moves, that the move is open),
start and goal, vertex conflicts (including an agent passing through a parked agent's goal) and
swap conflicts.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from planners.mapf.model import Cell, MapfInstance

MAX_ERRORS = 20


@dataclass(frozen=True)
class ValidationReport:
    """``errors`` is empty when the solution is valid; soc/makespan follow the model's costs."""

    errors: tuple[str, ...]
    soc: int
    makespan: int

    @property
    def valid(self) -> bool:
        return not self.errors


def _cost(path: Sequence[Cell]) -> int:
    t = len(path) - 1
    while t > 0 and tuple(path[t - 1]) == tuple(path[-1]):
        t -= 1
    return t


def _open(a: Cell, b: Cell, open_right: np.ndarray | None, open_down: np.ndarray | None) -> bool:
    """Whether the unit move between ``a`` and ``b`` (or a wait) is open."""
    (r0, c0), (r1, c1) = min(a, b), max(a, b)
    if r0 == r1 and c1 == c0 + 1 and open_right is not None:
        return bool(open_right[r0, c0])
    if c0 == c1 and r1 == r0 + 1 and open_down is not None:
        return bool(open_down[r0, c0])
    return True


def validate(
    instance: MapfInstance,
    paths: Sequence[Sequence[Cell]],
    open_right: np.ndarray | None = None,
    open_down: np.ndarray | None = None,
) -> ValidationReport:
    """Check ``paths`` (one per agent, ``(row, col)`` per time step) against ``instance``;
    ``open_right`` / ``open_down`` (as for ``GridGraph``), when given, say which moves to the
    right / down neighbour and back exist."""
    errors: list[str] = []
    names = instance.names
    rows, cols = instance.shape
    if len(paths) != instance.num_agents:
        errors.append(f"{len(paths)} paths for {instance.num_agents} agents")
        return ValidationReport(tuple(errors), 0, 0)
    paths = [[(int(r), int(c)) for r, c in p] for p in paths]
    for i, path in enumerate(paths):
        if not path:
            errors.append(f"{names[i]}: empty path")
            continue
        if path[0] != instance.starts[i]:
            errors.append(f"{names[i]}: starts at {path[0]}, not at its start {instance.starts[i]}")
        if path[-1] != instance.goals[i]:
            errors.append(f"{names[i]}: ends at {path[-1]}, not at its goal {instance.goals[i]}")
        for t, (r, c) in enumerate(path):
            if not (0 <= r < rows and 0 <= c < cols):
                errors.append(f"{names[i]}: t={t} cell {(r, c)} is outside the grid")
            elif not instance.free[r, c]:
                errors.append(f"{names[i]}: t={t} cell {(r, c)} is an obstacle")
            if t and abs(r - path[t - 1][0]) + abs(c - path[t - 1][1]) > 1:
                errors.append(f"{names[i]}: t={t} jumps from {path[t - 1]} to {(r, c)}")
            elif t and not _open(path[t - 1], (r, c), open_right, open_down):
                errors.append(f"{names[i]}: t={t} moves from {path[t - 1]} to {(r, c)}, closed")
    if any(not p for p in paths):
        return ValidationReport(tuple(errors[:MAX_ERRORS]), 0, 0)
    horizon = max(len(p) for p in paths)

    def at(i: int, t: int) -> Cell:
        return paths[i][min(t, len(paths[i]) - 1)]

    for t in range(horizon):
        seen: dict[Cell, int] = {}
        for i in range(len(paths)):
            cell = at(i, t)
            if cell in seen:
                errors.append(f"t={t}: {names[seen[cell]]} and {names[i]} both in {cell}")
            seen[cell] = i
        if t:
            steps = ((at(i, t - 1), at(i, t), i) for i in range(len(paths)))
            moves = {(a, b): i for a, b, i in steps if a != b}
            for (a, b), i in moves.items():
                j = moves.get((b, a))
                if j is not None and i < j:
                    errors.append(f"t={t}: {names[i]} and {names[j]} swap {a} and {b}")
        if len(errors) > MAX_ERRORS:
            break
    costs = [_cost(p) for p in paths]
    return ValidationReport(tuple(errors[:MAX_ERRORS]), sum(costs), max(costs))
