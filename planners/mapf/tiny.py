"""Random tiny instances checked against the brute-force optimum: ``fleet bench mapf --tiny``.

The class is the property test's, a little wider: grids of 2..5 × 2..5 cells where every cell
whose index is a multiple of 3 is an obstacle with probability one half, 2..4 agents with
distinct random starts and goals. Instances that fail the feasibility check, or that the brute
force (``brute_force``) finds no solution for, are drawn again (and counted). Instance i of seed
s comes from ``numpy.random.default_rng([s, i])``, so any one can be reproduced alone.

Every solver's solution goes through the validator; optimal solvers are checked for SOC equal
to the optimum, ECBS for ``lower_bound ≤ optimum ≤ SOC ≤ w · optimum``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from planners.mapf import solve, validate
from planners.mapf.brute_force import brute_force_soc
from planners.mapf.model import InfeasibleInstanceError, MapfInstance, check_instance

MAX_SIDE = 5
MAX_AGENTS = 4
OPTIMAL_SOLVERS = ("cbs", "cbs-plain")


@dataclass(frozen=True)
class TinyCase:
    """Instance ``index`` of ``seed`` and its brute-force optimum; ``redrawn`` rejected draws."""

    seed: int
    index: int
    instance: MapfInstance
    optimum: int
    redrawn: int


@dataclass(frozen=True)
class TinyRun:
    """One solver on one case: ``correct`` is optimal (CBS), within the bound (ECBS) or valid."""

    index: int
    solver: str
    status: str
    runtime_s: float
    soc: int | None
    correct: bool


def draw_instance(rng: np.random.Generator) -> MapfInstance:
    """One instance of the class (not yet checked for feasibility)."""
    rows, cols = (int(x) for x in rng.integers(2, MAX_SIDE + 1, size=2))
    index = np.arange(rows * cols).reshape(rows, cols)
    free = (index % 3 != 0) | (rng.random((rows, cols)) < 0.5)
    cells = [(int(r), int(c)) for r, c in np.argwhere(free)]
    k = int(rng.integers(2, min(MAX_AGENTS, len(cells) - 1) + 1)) if len(cells) > 2 else 1
    starts = [cells[i] for i in rng.permutation(len(cells))[:k]]
    goals = [cells[i] for i in rng.permutation(len(cells))[:k]]
    return MapfInstance(free, tuple(starts), tuple(goals))


def tiny_case(seed: int, index: int) -> TinyCase:
    """The ``index``-th case of ``seed``: the first feasible draw with a brute-force optimum."""
    rng = np.random.default_rng([seed, index])
    redrawn = 0
    while True:
        instance = draw_instance(rng)
        try:
            check_instance(instance)
        except InfeasibleInstanceError:
            redrawn += 1
            continue
        optimum = brute_force_soc(instance)
        if optimum is not None:
            return TinyCase(seed, index, instance, optimum, redrawn)
        redrawn += 1


def check_solver(case: TinyCase, solver: str, time_limit_s: float, w: float) -> TinyRun:
    """Run ``solver`` on the case and judge its answer against the optimum."""
    result = solve(case.instance, solver, w=w, time_limit_s=time_limit_s)
    correct = False
    if result.solution is not None and validate(case.instance, result.solution.paths).valid:
        soc = result.solution.soc
        if solver in OPTIMAL_SOLVERS:
            correct = soc == case.optimum
        elif solver == "ecbs":
            bound = result.lower_bound if result.lower_bound is not None else soc
            correct = bound <= case.optimum <= soc <= w * case.optimum + 1e-9
        else:
            correct = soc >= case.optimum
    return TinyRun(case.index, solver, result.status, result.runtime_s, result.soc, correct)


def run_tiny(
    count: int,
    seed: int,
    solvers: Sequence[str],
    time_limit_s: float,
    w: float,
    progress: Callable[[int], None] | None = None,
) -> tuple[list[TinyCase], list[TinyRun]]:
    """``count`` cases, every solver on each; ``progress(i)`` after case i."""
    cases: list[TinyCase] = []
    runs: list[TinyRun] = []
    for i in range(count):
        case = tiny_case(seed, i)
        cases.append(case)
        runs.extend(check_solver(case, solver, time_limit_s, w) for solver in solvers)
        if progress is not None:
            progress(i)
    return cases, runs


def summarize_tiny(
    cases: Sequence[TinyCase], runs: Sequence[TinyRun], solvers: Sequence[str]
) -> list[dict[str, object]]:
    """Per solver: solved and correct shares, p50 / p99 / max runtime, the slowest case."""
    rows = []
    by_index = {case.index: case for case in cases}
    for solver in solvers:
        mine = [r for r in runs if r.solver == solver]
        if not mine:
            continue
        times = np.array([r.runtime_s for r in mine])
        slowest = max(mine, key=lambda r: r.runtime_s)
        case = by_index[slowest.index]
        rows.append(
            {
                "solver": solver,
                "instances": len(mine),
                "solved": sum(r.status == "success" for r in mine) / len(mine),
                "correct": sum(r.correct for r in mine) / len(mine),
                "p50_s": float(np.percentile(times, 50)),
                "p99_s": float(np.percentile(times, 99)),
                "max_s": float(times.max()),
                "slowest": {
                    "index": slowest.index,
                    "status": slowest.status,
                    "optimum": case.optimum,
                    "instance": instance_literal(case.instance),
                },
                "failures": [r.index for r in mine if not r.correct][:20],
            }
        )
    return rows


def instance_literal(instance: MapfInstance) -> str:
    """Python source that rebuilds the instance (numpy imported as np)."""
    free = instance.free.astype(int).tolist()
    return (
        f"MapfInstance(np.array({free}, dtype=bool), starts={instance.starts}, "
        f"goals={instance.goals})"
    )
