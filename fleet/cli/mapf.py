"""``fleet plan mapf`` and ``fleet bench mapf``: multi-agent path finding on benchmark files."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from fleet.cli.options import JsonOpt

if TYPE_CHECKING:
    from fleet.bench.mapf import BenchConfig, BenchRun
    from planners.mapf import MapfInstance, MapfResult, ValidationReport

SOLVER_HELP = (
    "pp = prioritized planning with space-time A* and random restarts; sipp-pp = the same with "
    "SIPP; cbs = optimal ICBS (MDD cardinal conflicts, bypass, CG heuristic); cbs-plain = CBS "
    "without those; ecbs = bounded-suboptimal ECBS(w)."
)


# Exit statuses of `fleet plan mapf`, one per outcome a script may want to tell apart.
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_INVALID = 3
EXIT_TIMEOUT = 4
EXIT_INFEASIBLE = 5
EXIT_BY_STATUS = {"failed": EXIT_FAILED, "timeout": EXIT_TIMEOUT, "infeasible": EXIT_INFEASIBLE}


# `fleet bench mapf`'s options that take more than a line
TinyOpt = Annotated[
    int | None,
    typer.Option(
        min=1,
        help="Instead of the 32 x 32 maps: N random tiny instances (up to 5 x 5, up to 4 "
        "agents), every solver checked against a brute-force optimum.",
    ),
]
BenchTimeLimitOpt = Annotated[
    float | None,
    typer.Option(
        min=0.01,
        help="Seconds per instance before it counts as unsolved (default 5; 1 with --tiny).",
    ),
]
SolversOpt = Annotated[
    list[str] | None,
    typer.Option("--solver", help="Solvers to run (repeatable; default: all). " + SOLVER_HELP),
]
MapsOpt = Annotated[
    list[str] | None,
    typer.Option(
        "--map",
        help="Maps to run (repeatable; default: all generated ones): gen-random-10pct, "
        "gen-random-20pct, gen-rooms-7x7, gen-maze-2wide, gen-shelves; or the path of a "
        "MovingAI .map file, run on the .scen files beside it named after it.",
    ),
]
BenchWOpt = Annotated[
    float | None,
    typer.Option("--w", min=1.0, help="ECBS suboptimality bound (default 1.2; 1.5 with --tiny)."),
]
ScenariosOpt = Annotated[
    int, typer.Option(min=1, help="Scenarios (random start/goal sets) per map and k.")
]
KeepOpt = Annotated[
    Path | None,
    typer.Option(help="Keep the generated .map/.scen files in this directory."),
]


def register(
    app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app: typer.Typer
) -> None:
    plan_app.command("mapf")(plan_mapf)
    bench_app.command("mapf")(bench_mapf)


def _fail(message: str, code: int = EXIT_BAD_INPUT) -> None:
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
    as_json: JsonOpt = False,
    out: Annotated[
        Path | None,
        typer.Option(help="Write the schedule in libMultiRobotPlanning's output YAML format."),
    ] = None,
) -> None:
    """Solve a MAPF instance and print status, SOC, makespan, runtime and nodes expanded.

    The solution is checked by the independent validator (bounds, obstacles, unit moves,
    vertex/swap conflicts, goals) before anything is printed or written. Without a solution the
    reason and what to try go to stderr.

    Exit status: 0 solved; 1 prioritized planning failed (no priority order worked: PP is
    incomplete, a complete solver may still succeed); 2 bad input; 3 invalid solution (a
    solver bug); 4 timeout (--time-limit passed); 5 infeasible (proved to have no solution:
    an unreachable goal, two agents on one start or goal, or a complete search that ran out).

    Examples:

      fleet plan mapf random-32-32-10.map random-32-32-10-random-1.scen --agents 30 --solver cbs

      fleet plan mapf instance.yaml --solver ecbs --w 1.5 --out schedule.yaml
    """
    from rich.console import Console

    from planners.mapf import SOLVERS, solve, validate
    from planners.mapf.yaml_format import result_to_mapping, write_yaml

    if solver not in SOLVERS:
        _fail(f"--solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
    instance = _instance(map_file, scen_file, agents)
    result = solve(instance, solver, w=w, time_limit_s=time_limit, seed=seed)
    report = validate(instance, result.solution.paths) if result.solution else None
    summary = _plan_summary(result, solver, instance.num_agents, report)
    written = out is not None and result.solution is not None
    if written:
        write_yaml(out, result_to_mapping(instance, result))
    if as_json:
        print(json.dumps(summary))
    else:
        _print_plan(summary, f"MAPF {solver} on {map_file.name}, {instance.num_agents} agents")
        if written:
            Console().print(f"schedule written to {out}")
    _exit_unless_solved(solver, result, report)


def _exit_unless_solved(solver: str, result: MapfResult, report: ValidationReport | None) -> None:
    """Exit with the status of an invalid solution or of no solution, saying what to try."""
    if report is not None and not report.valid:
        _fail("invalid solution: " + "; ".join(report.errors), code=EXIT_INVALID)
    if result.status != "success":
        typer.echo(f"{solver}: {result.status}: {result.message}", err=True)
        hint = _hint(solver, result.status)
        if hint:
            typer.echo(hint, err=True)
        raise typer.Exit(EXIT_BY_STATUS[result.status])


def _instance(map_file: Path, scen_file: Path | None, agents: int | None) -> MapfInstance:
    """The instance of MAP_FILE (a YAML instance, or a MovingAI map with SCEN_FILE), its
    first ``agents`` agents; exits naming what is wrong with the files."""
    from planners.mapf.movingai import FormatError, load_instance
    from planners.mapf.yaml_format import read_instance

    try:
        if map_file.suffix.lower() in (".yaml", ".yml"):
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
    return instance


def _plan_summary(
    result: MapfResult, solver: str, agents: int, report: ValidationReport | None
) -> dict[str, Any]:
    """What `fleet plan mapf` prints of a solver's ``result`` and its validation."""
    summary: dict[str, Any] = {
        "status": result.status,
        "soc": result.soc,
        "makespan": result.makespan,
        "runtime_s": round(result.runtime_s, 6),
        "expanded": result.expanded,
        "expanded_high": result.expanded_high,
        "expanded_low": result.expanded_low,
        "lower_bound": result.lower_bound,
        "solver": solver,
        "agents": agents,
        "valid": None if report is None else report.valid,
        "message": result.message,
    }
    if report is not None and not report.valid:
        summary["errors"] = list(report.errors)
    return summary


def _print_plan(summary: dict[str, Any], title: str) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=title)
    table.add_column("field")
    table.add_column("value", justify="right")
    for key, value in summary.items():
        if key != "errors" and value not in (None, ""):
            table.add_row(key, str(value))
    Console().print(table)


def _hint(solver: str, status: str) -> str:
    """What to try after a solver found no solution."""
    if status == "failed" or (status == "timeout" and solver in ("pp", "sipp-pp")):
        return (
            "prioritized planning is incomplete: the complete solvers may still find a "
            "solution, try --solver cbs (optimal) or --solver ecbs (bounded suboptimal)"
        )
    if status == "timeout" and solver == "ecbs":
        return "try a larger --w, a longer --time-limit, or --solver cbs"
    if status == "timeout":
        return "try a longer --time-limit, or --solver ecbs (bounded suboptimal, faster)"
    return ""


def bench_mapf(
    as_json: JsonOpt = False,
    tiny: TinyOpt = None,
    time_limit: BenchTimeLimitOpt = None,
    solvers: SolversOpt = None,
    maps: MapsOpt = None,
    k_step: Annotated[int, typer.Option(min=1, help="Agents added per step.")] = 10,
    k_max: Annotated[int, typer.Option(min=1, help="Most agents tried.")] = 200,
    w: BenchWOpt = None,
    seed: Annotated[int, typer.Option(help="Seed of maps and scenarios (or tiny instances).")] = 0,
    scenarios: ScenariosOpt = 1,
    quick: Annotated[bool, typer.Option(help="Smoke run: 1 s limit, k = 20, 40, ... 100.")] = False,
    keep: KeepOpt = None,
) -> None:
    """For each solver and map, the largest number of agents solved within the time limit.

    The maps are generated here, 32 x 32 with fixed seeds, and written in the MovingAI format:
    gen-random-10pct and gen-random-20pct (random obstacles), gen-rooms-7x7 (7 x 7 rooms, one
    door per wall), gen-maze-2wide (a maze with 2-wide corridors), gen-shelves (2-deep shelves,
    2-wide aisles). They are not the MovingAI benchmark's maps, so figures published for those
    do not compare; --map PATH runs a MovingAI .map file of your own instead, on the first
    --scenarios of the PATH-stem-*.scen files beside it. Each step k uses the first k agents of
    each scenario, and a (map, solver) pair stops after a k where it solved none. Every
    solution is validated. cbs-plain (CBS without ICBS improvements) is the baseline for cbs.

    Default (about 3-5 minutes on 2 cores): --time-limit 5 --k-step 10 --k-max 200.

    The CBS target run: --map gen-random-10pct --solver cbs --solver cbs-plain --time-limit 60
    --k-step 5 --scenarios 3. On a MovingAI map of your own, for example:

      fleet bench mapf --map mapf-map/random-32-32-10.map --solver cbs --time-limit 60 --k-step 5

    With --tiny N: N seeded random instances of at most 5 x 5 cells and 4 agents, each solver
    checked against the brute-force optimum (cbs, cbs-plain: optimal; ecbs: within its bound;
    pp, sipp-pp: valid). Prints per solver the solved and correct shares, p50 / p99 / max
    runtime and the slowest instance, as Python that rebuilds it. Example:
    fleet bench mapf --tiny 2000 --seed 1
    """
    from fleet.bench.mapf import BenchConfig, chosen_maps, run_bench, user_suite
    from planners.mapf import SOLVERS
    from planners.mapf.movingai import FormatError

    chosen = list(solvers or SOLVERS)
    for name in chosen:
        if name not in SOLVERS:
            _fail(f"--solver must be among {', '.join(SOLVERS)}, got {name!r}")
    if tiny is not None:
        _bench_tiny(
            tiny, seed, chosen, 1.0 if time_limit is None else time_limit, w or 1.5, as_json
        )
        return
    try:
        generated, own = chosen_maps(maps or [], seed)
        own_files = user_suite(own, scenarios)
    except ValueError as err:
        _fail(str(err))
    if quick:
        time_limit, k_step, k_max = 1.0, 20, 100
    k_values = tuple(range(k_step, k_max + 1, k_step))
    limit = 5.0 if time_limit is None else time_limit
    config = BenchConfig(tuple(chosen), k_values, k_max, limit, w or 1.2, seed, scenarios)
    try:
        result = run_bench(config, generated, own_files, keep, None if as_json else _progress())
    except FormatError as err:
        _fail(str(err))
    if as_json:
        print(json.dumps(result))
    else:
        _print_bench(result, config)


def _progress() -> Callable[[BenchRun], None]:
    """A line on stderr per bench run."""
    from rich.console import Console

    console = Console(stderr=True)

    def progress(run: BenchRun) -> None:
        console.print(
            f"{run.map_name:16} {run.solver:9} scen {run.scenario} k={run.k:<4} "
            f"{run.status:8} {run.runtime_s:7.2f} s"
        )

    return progress


def _print_bench(result: dict[str, Any], config: BenchConfig) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(
        title=f"MAPF: largest k with all {config.scenarios} scenario(s) solved in "
        f"{config.time_limit_s:g} s"
    )
    for col in ("map", "solver", "max k", "s at max k", "valid", "k: solved, mean s"):
        table.add_column(col)
    for row in result["summary"]:
        solved, times = row["solved_by_k"], row["mean_runtime_by_k_s"]
        by_k = ", ".join(
            f"{k}: {n}" + (f" {times[k]:.2f}" if k in times else "") for k, n in solved.items()
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
    mismatches = result["cbs_soc_mismatches"]
    out.print(f"CBS variants with different SOC at the same k: {mismatches or 'none'}")


def _bench_tiny(
    count: int, seed: int, solvers: list[str], time_limit: float, w: float, as_json: bool
) -> None:
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

    from planners.mapf.tiny import run_tiny, summarize_tiny

    with Progress(
        "tiny instances",
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=Console(stderr=True),
        transient=True,
    ) as bar:
        task = bar.add_task("tiny", total=count)
        cases, runs = run_tiny(count, seed, solvers, time_limit, w, lambda _i: bar.advance(task))
    rows = summarize_tiny(cases, runs, solvers)
    config = {
        "instances": count,
        "seed": seed,
        "time_limit_s": time_limit,
        "w": w,
        "redrawn": sum(c.redrawn for c in cases),
    }
    if as_json:
        print(json.dumps({"config": config, "summary": rows}))
        return
    from rich.table import Table

    table = Table(
        title=f"MAPF on {count} tiny instances (seed {seed}, {time_limit:g} s each, w = {w:g})"
    )
    for col in ("solver", "solved", "correct", "p50 ms", "p99 ms", "max ms", "slowest"):
        table.add_column(col, justify="right")
    for row in rows:
        table.add_row(
            str(row["solver"]),
            f"{row['solved']:.2%}",
            f"{row['correct']:.2%}",
            f"{1000 * row['p50_s']:.1f}",  # type: ignore[operator]
            f"{1000 * row['p99_s']:.1f}",  # type: ignore[operator]
            f"{1000 * row['max_s']:.1f}",  # type: ignore[operator]
            f"#{row['slowest']['index']}",  # type: ignore[index]
        )
    out = Console()
    out.print(table)
    out.print(
        "correct: cbs, cbs-plain optimal; ecbs lower bound ≤ optimum ≤ SOC ≤ w · optimum; "
        f"pp, sipp-pp valid. {config['redrawn']} draws without a solution were redrawn."
    )
    for row in rows:
        slowest = row["slowest"]
        out.print(
            f"slowest for {row['solver']}: #{slowest['index']} "  # type: ignore[index]
            f"(tiny_case({seed}, {slowest['index']}), optimum {slowest['optimum']}, "  # type: ignore[index]
            f"{slowest['status']}): {slowest['instance']}",  # type: ignore[index]
            soft_wrap=True,
        )
        if row["failures"]:
            out.print(f"  {row['solver']} incorrect on #{row['failures']}")
