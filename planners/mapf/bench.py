"""The MAPF benchmark behind ``fleet bench mapf``: the largest k each solver solves per map.

Each map of ``generate.benchmark_maps`` is written as a MovingAI ``.map`` with one seeded
``.scen`` of ``k_max`` agents, read back through the parsers, and every solver runs on the first
k agents for k = k_step, 2·k_step, ... until it fails (timeout) or k_max. Every solution goes
through the validator; CBS runs also record whether their SOC equals the optimum found by the
other CBS variant at the same k.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from planners.mapf import solve, validate
from planners.mapf.generate import benchmark_maps, random_instance
from planners.mapf.grid_graph import GridGraph
from planners.mapf.movingai import load_instance, write_map, write_scen


@dataclass(frozen=True)
class BenchRun:
    map_name: str
    solver: str
    k: int
    status: str
    runtime_s: float
    soc: int | None
    lower_bound: int | None
    expanded: int
    valid: bool | None


def write_suite(
    directory: Path, k_max: int, seed: int, maps: Sequence[str] | None = None
) -> dict[str, tuple[Path, Path]]:
    """Write ``<name>.map`` and ``<name>.scen`` for each benchmark map; returns their paths."""
    out = {}
    for name, free in benchmark_maps(seed).items():
        if maps and name not in maps:
            continue
        k = min(k_max, int(free.sum()) // 2)
        map_path, scen_path = directory / f"{name}.map", directory / f"{name}.scen"
        write_map(map_path, free)
        write_scen(scen_path, f"{name}.map", random_instance(free, k, seed))
        out[name] = (map_path, scen_path)
    return out


def run_suite(
    files: dict[str, tuple[Path, Path]],
    solvers: Sequence[str],
    k_values: Sequence[int],
    time_limit_s: float,
    w: float,
    progress: Callable[[BenchRun], None] | None = None,
) -> list[BenchRun]:
    """Each solver on each map for increasing k, stopping a (map, solver) at its first failure."""
    runs: list[BenchRun] = []
    for name, (map_path, scen_path) in files.items():
        full = load_instance(map_path, scen_path)
        graph = GridGraph(full.free)
        for solver in solvers:
            for k in k_values:
                if k > full.num_agents:
                    break
                instance = full.first(k)
                result = solve(instance, solver, w=w, time_limit_s=time_limit_s, graph=graph)
                valid = None
                if result.solution is not None:
                    valid = validate(instance, result.solution.paths).valid
                run = BenchRun(
                    name,
                    solver,
                    k,
                    result.status,
                    result.runtime_s,
                    result.soc,
                    result.lower_bound,
                    result.expanded,
                    valid,
                )
                runs.append(run)
                if progress is not None:
                    progress(run)
                if result.status != "success":
                    break
    return runs


def summarize(runs: Sequence[BenchRun]) -> list[dict[str, object]]:
    """Per (map, solver): the largest k solved, its runtime, and the runtime at every k."""
    table: dict[tuple[str, str], dict[str, object]] = {}
    for run in runs:
        row = table.setdefault(
            (run.map_name, run.solver),
            {
                "map": run.map_name,
                "solver": run.solver,
                "max_k": 0,
                "runtime_at_max_k_s": None,
                "runtime_by_k": {},
                "all_valid": True,
            },
        )
        if run.status == "success":
            row["max_k"] = run.k
            row["runtime_at_max_k_s"] = round(run.runtime_s, 3)
            row["runtime_by_k"][run.k] = round(run.runtime_s, 3)  # type: ignore[index]
            row["all_valid"] = bool(row["all_valid"]) and bool(run.valid)
    return list(table.values())


def optimal_soc_mismatches(runs: Sequence[BenchRun]) -> list[tuple[str, int]]:
    """(map, k) where two optimal CBS variants returned different SOC (should be empty)."""
    socs: dict[tuple[str, int], set[int]] = {}
    for run in runs:
        if run.solver in ("cbs", "cbs-plain") and run.soc is not None:
            socs.setdefault((run.map_name, run.k), set()).add(run.soc)
    return sorted(key for key, values in socs.items() if len(values) > 1)
