"""``fleet bench mapf``: the largest k each solver solves per map.

Each map of ``generate.benchmark_maps`` is written as a MovingAI ``.map`` with ``scenarios``
seeded ``.scen`` files of ``k_max`` agents (or a user's own MovingAI files are taken,
``user_suite``), read back through the parsers, and every solver runs
on the first k agents of each scenario for k = k_step, 2·k_step, ... up to k_max, stopping after
the first k at which it solves none. Every solution goes through the validator; CBS runs also
record whether their SOC equals the optimum found by the other CBS variant at the same k.
:func:`run_bench` runs a whole bench (:class:`BenchConfig`) and gives what it prints.
"""

from __future__ import annotations

import re
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from planners.mapf import solve, validate
from planners.mapf.generate import benchmark_maps, random_instance
from planners.mapf.grid_graph import GridGraph
from planners.mapf.movingai import load_instance, write_map, write_scen


@dataclass(frozen=True)
class BenchRun:
    map_name: str
    solver: str
    scenario: int
    k: int
    status: str
    runtime_s: float
    soc: int | None
    lower_bound: int | None
    expanded: int
    valid: bool | None


def write_suite(
    directory: Path, k_max: int, seed: int, scenarios: int = 1, maps: Sequence[str] | None = None
) -> dict[str, tuple[Path, list[Path]]]:
    """Write ``<name>.map`` and ``<name>-<i>.scen`` per benchmark map; returns their paths."""
    out = {}
    for name, free in benchmark_maps(seed).items():
        if maps and name not in maps:
            continue
        k = min(k_max, int(free.sum()) // 2)
        map_path = directory / f"{name}.map"
        write_map(map_path, free)
        scens = []
        for i in range(scenarios):
            scen_path = directory / f"{name}-{i}.scen"
            write_scen(scen_path, f"{name}.map", random_instance(free, k, seed + 1000 * i))
            scens.append(scen_path)
        out[name] = (map_path, scens)
    return out


def user_suite(map_paths: Sequence[Path], scenarios: int) -> dict[str, tuple[Path, list[Path]]]:
    """The user's own MovingAI maps, each with the first ``scenarios`` of the ``.scen`` files
    beside it whose names start with the map's (``random-32-32-10-random-1.scen``, ...), in
    natural order; named by the map's file name."""
    out = {}
    for map_path in map_paths:
        scens = sorted(
            map_path.parent.glob(f"{map_path.stem}-*.scen"),
            key=lambda p: [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", p.name)],
        )
        if not scens:
            raise ValueError(f"no {map_path.stem}-*.scen beside {map_path}")
        out[map_path.stem] = (map_path, scens[:scenarios])
    return out


def run_suite(
    files: dict[str, tuple[Path, list[Path]]],
    solvers: Sequence[str],
    k_values: Sequence[int],
    time_limit_s: float,
    w: float,
    progress: Callable[[BenchRun], None] | None = None,
) -> list[BenchRun]:
    """Each solver on each map for increasing k, until a k at which no scenario is solved."""
    runs: list[BenchRun] = []
    for name, (map_path, scen_paths) in files.items():
        fulls = [load_instance(map_path, scen) for scen in scen_paths]
        graph = GridGraph(fulls[0].free)
        for solver in solvers:
            for k in k_values:
                if k > fulls[0].num_agents:
                    break
                solved = 0
                for i, full in enumerate(fulls):
                    instance = full.first(k)
                    result = solve(instance, solver, w=w, time_limit_s=time_limit_s, graph=graph)
                    valid = None
                    if result.solution is not None:
                        valid = validate(instance, result.solution.paths).valid
                    run = BenchRun(
                        name,
                        solver,
                        i,
                        k,
                        result.status,
                        result.runtime_s,
                        result.soc,
                        result.lower_bound,
                        result.expanded,
                        valid,
                    )
                    runs.append(run)
                    solved += result.status == "success"
                    if progress is not None:
                        progress(run)
                if not solved:
                    break
    return runs


def summarize(runs: Sequence[BenchRun]) -> list[dict[str, object]]:
    """Per (map, solver): the largest k with every scenario solved, solved counts and mean
    runtime (of the solved runs) at every k."""
    groups: dict[tuple[str, str], dict[int, list[BenchRun]]] = {}
    for run in runs:
        groups.setdefault((run.map_name, run.solver), {}).setdefault(run.k, []).append(run)
    rows = []
    for (name, solver), by_k in groups.items():
        max_k, at_max = 0, None
        solved_by_k, runtime_by_k = {}, {}
        valid = True
        for k, group in sorted(by_k.items()):
            ok = [r for r in group if r.status == "success"]
            solved_by_k[k] = f"{len(ok)}/{len(group)}"
            if ok:
                runtime_by_k[k] = round(sum(r.runtime_s for r in ok) / len(ok), 3)
                valid = valid and all(bool(r.valid) for r in ok)
            if len(ok) == len(group) and k > max_k:
                max_k, at_max = k, runtime_by_k[k]
        rows.append(
            {
                "map": name,
                "solver": solver,
                "max_k": max_k,
                "runtime_at_max_k_s": at_max,
                "solved_by_k": solved_by_k,
                "mean_runtime_by_k_s": runtime_by_k,
                "all_valid": valid,
            }
        )
    return rows


def optimal_soc_mismatches(runs: Sequence[BenchRun]) -> list[tuple[str, int, int]]:
    """(map, scenario, k) where the two optimal CBS variants disagree on SOC (should be none)."""
    socs: dict[tuple[str, int, int], set[int]] = {}
    for run in runs:
        if run.solver in ("cbs", "cbs-plain") and run.soc is not None:
            socs.setdefault((run.map_name, run.scenario, run.k), set()).add(run.soc)
    return sorted(key for key, values in socs.items() if len(values) > 1)


@dataclass(frozen=True)
class BenchConfig:
    """A bench: ``solvers`` on the first k agents of each of ``scenarios`` scenarios, k in
    ``k_values`` (the generated scenarios hold ``k_max`` agents), ``time_limit_s`` each, ECBS
    bound ``w``, maps and scenarios seeded by ``seed``."""

    solvers: tuple[str, ...]
    k_values: tuple[int, ...]
    k_max: int
    time_limit_s: float
    w: float
    seed: int
    scenarios: int

    def to_json(self) -> dict[str, Any]:
        return {
            "time_limit_s": self.time_limit_s,
            "k_values": list(self.k_values),
            "w": self.w,
            "seed": self.seed,
            "scenarios": self.scenarios,
        }


def chosen_maps(names: Sequence[str], seed: int) -> tuple[list[str], list[Path]]:
    """The generated maps among ``names`` and the user's own MovingAI .map files; ValueError
    naming one that is neither."""
    known = list(benchmark_maps(seed))
    generated = [name for name in names if name in known]
    own = [Path(name) for name in names if name not in known]
    for path in own:
        if path.suffix != ".map" or not path.is_file():
            raise ValueError(
                f"--map must be among {', '.join(known)} or a MovingAI .map file, got {str(path)!r}"
            )
    return generated, own


def run_bench(
    config: BenchConfig,
    generated: Sequence[str],
    own: dict[str, tuple[Path, list[Path]]],
    keep: Path | None = None,
    progress: Callable[[BenchRun], None] | None = None,
) -> dict[str, Any]:
    """The bench on the ``generated`` maps named (all of them when neither those nor ``own``,
    the user's files of :func:`user_suite`, are given), their files written to ``keep`` (else
    to a temporary directory); its config, the summary per map and solver, the CBS variants'
    SOC mismatches and every run. FormatError from a file that does not parse."""
    with tempfile.TemporaryDirectory() as tmp:
        directory = keep or Path(tmp)
        directory.mkdir(parents=True, exist_ok=True)
        files = {}
        if generated or not own:
            files = write_suite(directory, config.k_max, config.seed, config.scenarios, generated)
        runs = run_suite(
            {**files, **own},
            config.solvers,
            config.k_values,
            config.time_limit_s,
            config.w,
            progress,
        )
    return {
        "config": config.to_json(),
        "summary": summarize(runs),
        "cbs_soc_mismatches": optimal_soc_mismatches(runs),
        "runs": [run.__dict__ for run in runs],
    }
