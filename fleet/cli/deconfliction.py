"""``fleet bench deconfliction``: how long planning all transits of a round takes."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Annotated

import typer

from fleet.cli.options import JsonOpt

# the fleets' stress worlds: (world, robots)
STRESS_WORLDS = (("corridor", 3), ("home", 6))
# wall seconds a fleet run may take before it counts as a deadlock
FLEET_TIMEOUT_S = 900.0
# warehouse-like grid: planners.mapf.generate's shelf map, each of its cells this many metres
WAREHOUSE_CELL_M = 0.5
WAREHOUSE_CELLS = 40
# the family's table of runs needs this many columns of text
RUNS_TABLE_COLUMNS = 110


def register(app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app) -> None:
    bench_app.command("deconfliction")(bench_deconfliction)


def _warehouse(resolution: float):
    """A GridMap of the generated shelf warehouse (2-deep shelves, 2-wide aisles)."""
    import numpy as np

    from planners.grid import GridMap
    from planners.mapf.generate import warehouse_map

    free = warehouse_map(WAREHOUSE_CELLS, WAREHOUSE_CELLS)
    k = round(WAREHOUSE_CELL_M / resolution)
    occupied = np.kron(~free, np.ones((k, k), dtype=bool)).astype(bool)
    occupied[:, :1] = occupied[:, -1:] = occupied[:1, :] = occupied[-1:, :] = True
    return GridMap(occupied, np.zeros_like(occupied), resolution, (0.0, 0.0))


def _round(graph, robots: int, rng, stagger_s: float):
    """Random distinct start and goal cells in the graph's largest component, start times
    uniform in [0, stagger_s]."""
    import numpy as np

    from planners.deconfliction import TransitRequest

    main = np.bincount(graph.component[graph.usable]).argmax()
    cells = np.argwhere(graph.component == main)
    starts = cells[rng.permutation(len(cells))[:robots]]
    goals = cells[rng.permutation(len(cells))[:robots]]
    return [
        TransitRequest(
            f"robot-{i}",
            graph.point(tuple(s)),
            graph.point(tuple(g)),
            float(rng.uniform(0.0, stagger_s)),
        )
        for i, (s, g) in enumerate(zip(starts, goals, strict=True))
    ]


def bench_deconfliction(
    rounds: int = typer.Option(50, min=1, help="Rounds per scenario (seeded: round i, seed i)."),
    joint_time_limit: float = typer.Option(
        1.0, help="Seconds the joint fallback (CBS, or ECBS above 10 robots) may take."
    ),
    as_json: JsonOpt = False,
    fleet_seeds: str = typer.Option(
        "",
        "--fleet-seeds",
        help="Also run whole fleets on the stress worlds (corridor with 3 robots, home with 6) "
        "under each mode, for these seeds (0-9, or 0,1,2); none by default, as each run takes "
        "a minute or two.",
    ),
    modes: str = typer.Option(
        "local,prioritized,cbs", help="Comma-separated modes the fleets run under."
    ),
    fleet_worlds: str = typer.Option(
        "corridor,home",
        help="Comma-separated stress worlds the fleets run on: corridor (3 robots), home (6).",
    ),
    run_root: Annotated[
        Path | None,
        typer.Option(
            "--run-root", help="Where the fleets' run dirs go (default: runs/bench-deconf-<time>)."
        ),
    ] = None,
    family: bool = typer.Option(
        False,
        "--family",
        help="Run only whole fleets on the generated family of stress worlds (two or three "
        "rooms, corridors 0.45-0.9 m wide and 1-4 m long, a doorway, an L), every member under "
        "every mode of --modes, and judge each mode against issue 30's targets (PASS/FAIL). "
        "No planning rounds are timed then.",
    ),
    family_seeds: str = typer.Option(
        "0-2", "--family-seeds", help="Seeds of the family's fleets (0-2, or 0,1,2)."
    ),
    family_members: str = typer.Option(
        "all",
        "--family-members",
        help="Comma-separated members of the family to run (all by default): "
        "c0.45x2.5, c0.6x1, c0.6x4, c0.75x2.5, c0.9x2.5, door0.8, L0.6, 3rooms0.6.",
    ),
) -> None:
    """Time planning all transits of a round (planners/deconfliction.py) on a transit graph,
    and with --fleet-seeds run `fleet up --deconfliction MODE` side by side on stress worlds.

    Scenarios: 6 robots on home (target ≤ 50 ms a round) and 50 robots on a generated warehouse
    of shelves (target ≤ 1 s). Each round draws random distinct start and goal cells and start
    times within 2 s, seeded by the round's number. The robot's radius, wall clearance and
    transit speed come from configs/fleet.yaml. Reports the graph's build time and cells, the
    median and 95th-percentile planning time per round, how many rounds needed the joint
    fallback (CBS, or ECBS above 10 robots) and how many failed, and whether every plan passed
    the MAPF validator, closed moves included.

    Fleets (`--fleet-seeds`): per world and mode, runs finished (a run that did not finish
    within 15 minutes of wall time counts as a deadlock), robot–robot and robot–wall contacts,
    waiting (robot-seconds held before shared cells plus given way to peers), makespan, and
    waypoints given up; each run's dir keeps its report. Example: `fleet bench deconfliction
    --fleet-seeds 0-9 --json`.

    The generated family (`--family`, fleet/bench/world_family.py): eight worlds named by their
    passage: c<width>x<length> (two rooms of 3.4 × 3 m joined by a straight corridor, width
    face to face), door0.8 (a gap in the wall between two rooms), L0.6 (an L-shaped corridor)
    and 3rooms0.6 (three rooms in a row). A table in each room, two robots starting in the
    first room and two in the last, so the passages are crossed both ways. The worlds are
    written to <run-root>/worlds/. Each fleet runs `fleet up --until-done --headless --speed 0
    --deconfliction MODE`, one at a time, each in <run-root>/<member>-<mode>-seed<N>/; a line
    per run as it ends. Per run: finished, coverage, robot–robot and robot–wall contacts,
    makespan, the coordinator's "unreachable" events and waypoints given up. Per mode, the
    targets: no "unreachable" event (every member's goals are reachable on the grid), every run
    done with coverage ≥ 0.95, no robot–robot contact, and the median of its makespan over
    local's on the same member and seed ≤ 1; PASS when all hold. Example: `fleet bench
    deconfliction --family --family-seeds 0 --modes local,prioritized --run-root
    runs/family`.
    """
    if family:
        _family(family_members, family_seeds, modes, run_root, as_json)
        return
    import numpy as np

    from fleet.config import resolve_world
    from fleet.coordinator.transits import GRAPH_RESOLUTION
    from fleet.params import load_fleet_config
    from fleet.world import load_world
    from planners.deconfliction import plan_round
    from planners.mapf import validate
    from planners.transit_graph import build_transit_graph

    cfg = load_fleet_config()
    radius, clearance = cfg.robot.radius, cfg.coordinator.wall_clearance
    speed, resolution = cfg.agent.transit_speed, 0.05
    scenarios = {
        # home on the coordinator's own graph grid; the warehouse is drawn on 5 cm cells
        "home": (lambda: load_world(resolve_world("home")).grid(GRAPH_RESOLUTION), 6, 0.05),
        "warehouse": (lambda: _warehouse(resolution), 50, 1.0),
    }
    results = {}
    for name, (grid_of, robots, target_s) in scenarios.items():
        grid = grid_of()
        t0 = time.perf_counter()
        graph = build_transit_graph(grid, radius, clearance)
        build_s = time.perf_counter() - t0
        times, cbs, ecbs, failed, invalid = [], 0, 0, 0, 0
        for seed in range(rounds):
            requests = _round(graph, robots, np.random.default_rng(seed), 2.0)
            t0 = time.perf_counter()
            plan = plan_round(graph, requests, speed, joint_time_limit_s=joint_time_limit)
            times.append(time.perf_counter() - t0)
            cbs += plan.method == "cbs"
            ecbs += plan.method == "ecbs"
            if plan.status != "success":
                failed += 1
            else:
                paths = [t.cells for t in plan.transits]
                report = validate(plan.instance, paths, graph.open_right, graph.open_down)
                invalid += not report.valid
        results[name] = {
            "robots": robots,
            "rounds": rounds,
            "graph_cells": graph.num_cells,
            "graph_build_ms": round(build_s * 1e3, 1),
            "plan_ms_median": round(float(np.median(times)) * 1e3, 2),
            "plan_ms_p95": round(float(np.percentile(times, 95)) * 1e3, 2),
            "target_ms": target_s * 1e3,
            "rounds_cbs": cbs,
            "rounds_ecbs": ecbs,
            "rounds_failed": failed,
            "plans_invalid": invalid,
        }
    if fleet_seeds:
        results["fleets"] = _fleets(fleet_seeds, modes, fleet_worlds, run_root)
    if as_json:
        typer.echo(json.dumps(results))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title="Deconfliction: planning all transits of a round")
    table.add_column("metric")
    for name in results:
        table.add_column(name, justify="right")
    planned = {k: v for k, v in results.items() if k != "fleets"}
    for key in next(iter(planned.values())):
        table.add_row(key, *(str(r[key]) for r in planned.values()))
    Console().print(table)
    if "fleets" in results:
        fleets = Table(title="Deconfliction: whole fleets (medians over seeds; totals)")
        for col in (
            "world / mode",
            "finished",
            "robot contacts",
            "wall contacts",
            "waiting s",
            "makespan s",
            "given up",
        ):
            fleets.add_column(col, justify="right")
        for name, row in results["fleets"].items():
            fleets.add_row(name, *(str(v) for v in row.values()))
        Console().print(fleets)


def _modes(modes: str) -> list[str]:
    """The modes of ``--modes``; exits naming an unknown one."""
    from fleet.cli.common import _fail
    from fleet.params import DECONFLICTION_MODES

    chosen = [m.strip() for m in modes.split(",") if m.strip()]
    bad = [m for m in chosen if m not in DECONFLICTION_MODES]
    if bad or not chosen:
        _fail(
            f"--modes: {', '.join(bad) or 'none given'}; choose from "
            f"{', '.join(DECONFLICTION_MODES)}"
        )
    return chosen


def _run_fleets(scenarios: list, seeds: list[int], root: Path) -> dict:
    """``fleet bench fleet``'s runner on ``scenarios`` (one fleet at a time, progress on
    stderr); its result, also kept in ``root / bench.json``."""
    from fleet.bench.fleet import run_bench

    return run_bench(
        root,
        scenarios,
        seeds,
        0.0,
        FLEET_TIMEOUT_S,
        lambda line: print(line, file=sys.stderr, flush=True),
    )


def _default_root(run_root: Path | None) -> Path:
    from datetime import datetime

    return run_root or Path("runs") / datetime.now().strftime("bench-deconf-%Y%m%d-%H%M%S")


def _fleets(seeds: str, modes: str, worlds: str, run_root: Path | None) -> dict[str, dict]:
    """Whole fleets on the stress worlds under each mode (see the command's help)."""
    import numpy as np

    from fleet.bench.fleet import Scenario
    from fleet.cli.common import _fail, parse_seeds
    from fleet.config import resolve_world

    chosen, seed_list = _modes(modes), parse_seeds(seeds)
    stress = dict(STRESS_WORLDS)
    names = [w.strip() for w in worlds.split(",") if w.strip()]
    unknown = [w for w in names if w not in stress]
    if unknown or not names:
        _fail(
            f"--fleet-worlds: {', '.join(unknown) or 'none given'}; choose from {', '.join(stress)}"
        )
    scenarios = [
        Scenario(
            f"{world}-{robots}/{mode}", str(resolve_world(world)), robots, ("--deconfliction", mode)
        )
        for world, robots in STRESS_WORLDS
        if world in names
        for mode in chosen
    ]
    result = _run_fleets(scenarios, seed_list, _default_root(run_root))
    out = {}
    for sc in scenarios:
        runs = [r for r in result["runs"] if r["world"] == sc.name and r["status"] != "no report"]
        summary = result["worlds"][sc.name]
        waits = [r["time_s"]["hold"] + r["time_s"]["yield"] for r in runs]
        out[sc.name] = {
            "finished": f"{summary['finished']}/{summary['runs']}",
            "robot_contacts": sum(r["contacts"]["robot_robot"] for r in runs),
            "wall_contacts": sum(r["contacts"]["robot_wall"] for r in runs),
            "waiting_s_median": round(float(np.median(waits)), 1) if waits else None,
            "makespan_s_median": summary["makespan_s"],
            "given_up": summary["skipped_total"],
        }
    return out


def _family(names: str, seeds: str, modes: str, run_root: Path | None, as_json: bool) -> None:
    """Whole fleets on the generated family under each mode, and each mode's verdict (see the
    command's help)."""
    from fleet.bench.family_verdict import family_run, family_summary
    from fleet.bench.fleet import Scenario
    from fleet.bench.world_family import layout, members, write_world
    from fleet.cli.common import _fail, parse_seeds

    chosen, seed_list = _modes(modes), parse_seeds(seeds)
    try:
        family = members(names)
    except ValueError as e:
        _fail(f"--family-members: {e}")
    root = _default_root(run_root)
    scenarios = [
        Scenario(
            f"{m.name}/{mode}",
            str(write_world(m, root / "worlds")),
            len(layout(m).starts),
            ("--deconfliction", mode),
        )
        for m in family
        for mode in chosen
    ]
    result = _run_fleets(scenarios, seed_list, root)
    runs = [family_run(r) for r in result["runs"]]
    out = {"root": str(root), "runs": runs, "modes": family_summary(runs)}
    (root / "family.json").write_text(json.dumps(out, indent=2) + "\n")
    if as_json:
        typer.echo(json.dumps(out))
        return
    _print_family(out)


def _print_family(out: dict) -> None:
    """The family's runs (a row per member, mode and seed) and, a column per mode, the modes'
    figures, checks and verdicts."""
    from rich.console import Console
    from rich.table import Table

    from fleet.bench.family_verdict import CHECKS

    def pct(v: float | None) -> str:
        return "–" if v is None else f"{100 * v:.1f} %"

    runs = Table(title="Deconfliction: the generated family, whole fleets")
    for col in ("member", "mode", "seed", "status", "coverage", "contacts robot / wall"):
        runs.add_column(col, justify="right")
    for col in ("makespan s", "unreachable", "given up"):
        runs.add_column(col, justify="right")
    for r in out["runs"]:
        unreachable = r["unreachable"]
        runs.add_row(
            *(str(r[k]) for k in ("member", "mode", "seed", "status")),
            pct(r["coverage"]),
            f"{r['robot_contacts']} / {r['wall_contacts']}",
            str(r["makespan_s"]),
            "–" if unreachable is None else str(len(unreachable)),
            str(r["given_up"]),
        )
    # a row holds nine figures: wider than a pipe's 80 columns, so the table is never cut
    Console(width=max(RUNS_TABLE_COLUMNS, Console().width)).print(runs)
    modes = out["modes"]
    verdicts = Table(title="Per mode, against issue 30's targets")
    verdicts.add_column("")
    for mode in modes:
        verdicts.add_column(mode, justify="right")
    rows = {
        "finished": lambda s: f"{s['finished']}/{s['runs']}",
        "unreachable events": lambda s: str(s["unreachable"]),
        "coverage, least": lambda s: pct(s["coverage_min"]),
        "contacts robot / wall": lambda s: f"{s['robot_contacts']} / {s['wall_contacts']}",
        "makespan median s": lambda s: str(s["makespan_s_median"]),
        "makespan / local's, median": lambda s: str(s["makespan_over_local_median"] or "–"),
        "waypoints given up": lambda s: str(s["given_up"]),
    }
    for label, cell in rows.items():
        verdicts.add_row(label, *(cell(s) for s in modes.values()))
    marks = {True: "pass", False: "FAIL", None: "–"}
    for check in CHECKS:
        verdicts.add_row(check, *(marks[s["checks"][check]] for s in modes.values()))
    verdicts.add_row("verdict", *(s["verdict"] for s in modes.values()))
    Console().print(verdicts)
