"""``fleet plan mapf`` and ``fleet bench mapf``: multi-agent path finding on benchmark files."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Annotated

import typer

SOLVER_HELP = (
    "pp = prioritized planning with space-time A* and random restarts; sipp-pp = the same with "
    "SIPP; cbs = optimal ICBS (MDD cardinal conflicts, bypass, CG heuristic); cbs-plain = CBS "
    "without those; ecbs = bounded-suboptimal ECBS(w)."
)


def register(
    app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app: typer.Typer
) -> None:
    plan_app.command("mapf")(plan_mapf)
    bench_app.command("mapf")(bench_mapf)


def _fail(message: str, code: int = 2) -> None:
    typer.echo(f"error: {message}", err=True)
    raise typer.Exit(code)


def plan_mapf(
    map_file: Annotated[
        Path,
        typer.Argument(
            exists=True,
            dir_okay=False,
            help="A MovingAI .map file, or a libMultiRobotPlanning YAML instance "
            "(map.dimensions, map.obstacles, agents) - then leave SCEN_FILE out.",
        ),
    ],
    scen_file: Annotated[
        Path | None,
        typer.Argument(
            exists=True,
            dir_okay=False,
            help="A MovingAI .scen file (x = column, y = row from the top).",
        ),
    ] = None,
    agents: Annotated[
        int | None,
        typer.Option("--agents", "-k", min=1, help="Use the first K agents (default: all)."),
    ] = None,
    solver: Annotated[str, typer.Option(help=SOLVER_HELP)] = "cbs",
    w: Annotated[float, typer.Option("--w", min=1.0, help="ECBS suboptimality bound.")] = 1.2,
    time_limit: Annotated[
        float, typer.Option(min=0.0, help="Seconds before giving up with status timeout.")
    ] = 60.0,
    seed: Annotated[int, typer.Option(help="Seed of PP's restart shuffles.")] = 0,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    out: Annotated[
        Path | None,
        typer.Option(help="Write the schedule in libMultiRobotPlanning's output YAML format."),
    ] = None,
) -> None:
    """Solve a MAPF instance and print status, SOC, makespan, runtime and nodes expanded.

    The solution is checked by the independent validator (bounds, obstacles, unit moves,
    vertex/swap conflicts, goals) before anything is printed or written.

    Examples:

      fleet plan mapf random-32-32-10.map random-32-32-10-random-1.scen --agents 30 --solver cbs

      fleet plan mapf instance.yaml --solver ecbs --w 1.5 --out schedule.yaml
    """
    from planners.mapf import SOLVERS, solve, validate
    from planners.mapf.movingai import FormatError, load_instance
    from planners.mapf.yaml_format import read_instance, result_to_mapping, write_yaml

    if solver not in SOLVERS:
        _fail(f"--solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
    is_yaml = map_file.suffix.lower() in (".yaml", ".yml")
    try:
        if is_yaml:
            if scen_file is not None:
                _fail(f"{map_file} is a YAML instance: leave SCEN out")
            instance = read_instance(map_file)
            if agents is not None:
                instance = instance.first(min(agents, instance.num_agents))
        else:
            if scen_file is None:
                _fail(f"{map_file} is a MovingAI map: give a .scen file too")
            instance = load_instance(map_file, scen_file, agents)
    except (FormatError, ValueError) as err:
        _fail(str(err))
    result = solve(instance, solver, w=w, time_limit_s=time_limit, seed=seed)
    report = validate(instance, result.solution.paths) if result.solution else None
    summary = {
        "status": result.status,
        "soc": result.soc,
        "makespan": result.makespan,
        "runtime_s": round(result.runtime_s, 6),
        "expanded": result.expanded,
        "expanded_high": result.expanded_high,
        "expanded_low": result.expanded_low,
        "lower_bound": result.lower_bound,
        "solver": solver,
        "agents": instance.num_agents,
        "valid": None if report is None else report.valid,
        "message": result.message,
    }
    if report is not None and not report.valid:
        summary["errors"] = list(report.errors)
    if out is not None and result.solution is not None:
        write_yaml(out, result_to_mapping(instance, result))
    if as_json:
        print(json.dumps(summary))
    else:
        from rich.console import Console
        from rich.table import Table

        table = Table(title=f"MAPF {solver} on {map_file.name}, {instance.num_agents} agents")
        table.add_column("field")
        table.add_column("value", justify="right")
        for key, value in summary.items():
            if key != "errors" and value not in (None, ""):
                table.add_row(key, str(value))
        Console().print(table)
        if out is not None and result.solution is not None:
            Console().print(f"schedule written to {out}")
    if result.status == "infeasible":
        raise typer.Exit(1)
    if report is not None and not report.valid:
        _fail("invalid solution: " + "; ".join(report.errors), code=3)


def bench_mapf(
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    time_limit: Annotated[
        float, typer.Option(min=0.1, help="Seconds per instance before it counts as unsolved.")
    ] = 5.0,
    solvers: Annotated[
        list[str] | None,
        typer.Option("--solver", help="Solvers to run (repeatable; default: all). " + SOLVER_HELP),
    ] = None,
    maps: Annotated[
        list[str] | None,
        typer.Option(
            "--map",
            help="Maps to run (repeatable; default: all): random-32-32-10, random-32-32-20, "
            "room-32-32-7, maze-32-32-2, warehouse-32-32.",
        ),
    ] = None,
    k_step: Annotated[int, typer.Option(min=1, help="Agents added per step.")] = 10,
    k_max: Annotated[int, typer.Option(min=1, help="Most agents tried.")] = 200,
    w: Annotated[float, typer.Option("--w", min=1.0, help="ECBS suboptimality bound.")] = 1.2,
    seed: Annotated[int, typer.Option(help="Seed of maps and scenarios.")] = 0,
    scenarios: Annotated[
        int, typer.Option(min=1, help="Scenarios (random start/goal sets) per map and k.")
    ] = 1,
    quick: Annotated[bool, typer.Option(help="Smoke run: 1 s limit, k = 20, 40, ... 100.")] = False,
    keep: Annotated[
        Path | None,
        typer.Option(help="Keep the generated .map/.scen files in this directory."),
    ] = None,
) -> None:
    """For each solver and map, the largest number of agents solved within the time limit.

    Maps are 32 x 32, built with fixed seeds and written in the MovingAI format (random 10% and
    20% obstacles, rooms, a maze with 2-wide corridors, a warehouse); each step k uses the first k
    agents of each scenario, and a (map, solver) pair stops after a k where it solved none. Every
    solution is validated. cbs-plain (CBS without ICBS improvements) is the baseline for cbs.

    Default (about 3-5 minutes on 2 cores): --time-limit 5 --k-step 10 --k-max 200.
    The CBS target run: fleet bench mapf --map random-32-32-10 --solver cbs --solver cbs-plain
    --time-limit 60 --k-step 5 --scenarios 3
    """
    from planners.mapf import SOLVERS
    from planners.mapf.bench import optimal_soc_mismatches, run_suite, summarize, write_suite
    from planners.mapf.generate import benchmark_maps

    chosen = list(solvers or SOLVERS)
    for name in chosen:
        if name not in SOLVERS:
            _fail(f"--solver must be among {', '.join(SOLVERS)}, got {name!r}")
    known = list(benchmark_maps(seed))
    for name in maps or []:
        if name not in known:
            _fail(f"--map must be among {', '.join(known)}, got {name!r}")
    if quick:
        time_limit, k_step, k_max = 1.0, 20, 100
    k_values = list(range(k_step, k_max + 1, k_step))

    from rich.console import Console

    console = Console(stderr=True)

    def progress(run: object) -> None:
        if not as_json:
            console.print(
                f"{run.map_name:16} {run.solver:9} scen {run.scenario} k={run.k:<4} "  # type: ignore[attr-defined]
                f"{run.status:8} "  # type: ignore[attr-defined]
                f"{run.runtime_s:7.2f} s"  # type: ignore[attr-defined]
            )

    with tempfile.TemporaryDirectory() as tmp:
        directory = keep or Path(tmp)
        directory.mkdir(parents=True, exist_ok=True)
        files = write_suite(directory, k_max, seed, scenarios, maps)
        runs = run_suite(files, chosen, k_values, time_limit, w, progress)
    rows = summarize(runs)
    mismatches = optimal_soc_mismatches(runs)
    config = {
        "time_limit_s": time_limit,
        "k_values": k_values,
        "w": w,
        "seed": seed,
        "scenarios": scenarios,
    }
    if as_json:
        print(
            json.dumps(
                {
                    "config": config,
                    "summary": rows,
                    "cbs_soc_mismatches": mismatches,
                    "runs": [run.__dict__ for run in runs],
                }
            )
        )
        return
    from rich.table import Table

    table = Table(
        title=f"MAPF: largest k with all {scenarios} scenario(s) solved in {time_limit:g} s"
    )
    for col in ("map", "solver", "max k", "s at max k", "valid", "k: solved, mean s"):
        table.add_column(col)
    for row in rows:
        solved, times = row["solved_by_k"], row["mean_runtime_by_k_s"]
        by_k = ", ".join(
            f"{k}: {n}" + (f" {times[k]:.2f}" if k in times else "")  # type: ignore[index,operator]
            for k, n in solved.items()  # type: ignore[union-attr]
        )
        table.add_row(
            str(row["map"]),
            str(row["solver"]),
            str(row["max_k"]),
            str(row["runtime_at_max_k_s"]),
            str(row["all_valid"]),
            by_k,
        )
    out = Console()
    out.print(table)
    out.print(f"CBS variants with different SOC at the same k: {mismatches or 'none'}")
