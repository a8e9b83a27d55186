"""``fleet bench deconfliction``: how long planning all transits of a round takes
(:func:`time_rounds`), and whole fleets under each deconfliction mode, on the stress worlds
(:func:`run_stress_fleets`) or on the generated family (:func:`run_family`, judged by
``fleet.bench.family_verdict``)."""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fleet.bench.family_verdict import family_run, family_summary
from fleet.bench.fleet import Scenario, run_bench
from fleet.bench.world_family import FamilyMember, layout, write_world
from fleet.config import resolve_world
from fleet.coordinator.transits import GRAPH_RESOLUTION
from fleet.params import FleetConfig
from fleet.world import load_world
from planners.deconfliction import TransitRequest, plan_round
from planners.grid import GridMap
from planners.mapf import validate
from planners.mapf.generate import warehouse_map
from planners.transit_graph import TransitGraph, build_transit_graph

# the fleets' stress worlds: (world, robots)
STRESS_WORLDS = (("corridor", 3), ("home", 6))
# wall seconds a fleet run may take before it counts as a deadlock
FLEET_TIMEOUT_S = 900.0
# warehouse-like grid: planners.mapf.generate's shelf map, each of its cells this many metres
WAREHOUSE_CELL_M = 0.5
WAREHOUSE_CELLS = 40
# the warehouse is drawn on cells of this size (m)
WAREHOUSE_RESOLUTION = 0.05
# start times of a timed round are drawn within this many seconds
STAGGER_S = 2.0


def warehouse(resolution: float) -> GridMap:
    """A GridMap of the generated shelf warehouse (2-deep shelves, 2-wide aisles)."""
    free = warehouse_map(WAREHOUSE_CELLS, WAREHOUSE_CELLS)
    k = round(WAREHOUSE_CELL_M / resolution)
    occupied = np.kron(~free, np.ones((k, k), dtype=bool)).astype(bool)
    occupied[:, :1] = occupied[:, -1:] = occupied[:1, :] = occupied[-1:, :] = True
    return GridMap(occupied, np.zeros_like(occupied), resolution, (0.0, 0.0))


def random_round(
    graph: TransitGraph, robots: int, rng: np.random.Generator, stagger_s: float
) -> list[TransitRequest]:
    """Random distinct start and goal cells in the graph's largest component, start times
    uniform in [0, stagger_s]."""
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


def time_rounds(cfg: FleetConfig, rounds: int, joint_time_limit_s: float) -> dict[str, Any]:
    """Per scenario (6 robots on home, on the coordinator's own graph grid; 50 on the
    warehouse), ``rounds`` seeded rounds planned on its transit graph: the graph's build time
    and cells, the median and 95th-percentile planning time, the rounds that needed the joint
    fallback or failed, and the plans the validator refused."""
    scenarios: dict[str, tuple[Callable[[], GridMap], int, float]] = {
        "home": (lambda: load_world(resolve_world("home")).grid(GRAPH_RESOLUTION), 6, 0.05),
        "warehouse": (lambda: warehouse(WAREHOUSE_RESOLUTION), 50, 1.0),
    }
    return {
        name: _time_scenario(cfg, grid_of(), robots, target_s, rounds, joint_time_limit_s)
        for name, (grid_of, robots, target_s) in scenarios.items()
    }


def _time_scenario(
    cfg: FleetConfig,
    grid: GridMap,
    robots: int,
    target_s: float,
    rounds: int,
    joint_time_limit_s: float,
) -> dict[str, Any]:
    radius, clearance = cfg.robot.radius, cfg.coordinator.wall_clearance
    t0 = time.perf_counter()
    graph = build_transit_graph(grid, radius, clearance)
    build_s = time.perf_counter() - t0
    times, cbs, ecbs, failed, invalid = [], 0, 0, 0, 0
    for seed in range(rounds):
        requests = random_round(graph, robots, np.random.default_rng(seed), STAGGER_S)
        t0 = time.perf_counter()
        plan = plan_round(
            graph, requests, cfg.agent.transit_speed, joint_time_limit_s=joint_time_limit_s
        )
        times.append(time.perf_counter() - t0)
        cbs += plan.method == "cbs"
        ecbs += plan.method == "ecbs"
        if plan.status != "success":
            failed += 1
        else:
            paths = [t.cells for t in plan.transits]
            report = validate(plan.instance, paths, graph.open_right, graph.open_down)
            invalid += not report.valid
    return {
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


def run_fleets(scenarios: list[Scenario], seeds: list[int], root: Path) -> dict[str, Any]:
    """``fleet bench fleet``'s runner on ``scenarios`` (one fleet at a time, progress on
    stderr); its result, also kept in ``root / bench.json``."""
    return run_bench(
        root,
        scenarios,
        seeds,
        0.0,
        FLEET_TIMEOUT_S,
        lambda line: print(line, file=sys.stderr, flush=True),
    )


def run_stress_fleets(
    worlds: Sequence[str], modes: Sequence[str], seeds: list[int], root: Path
) -> dict[str, dict[str, Any]]:
    """Whole fleets on the stress ``worlds`` (of STRESS_WORLDS) under each mode, per world and
    mode: runs finished, robot–robot and robot–wall contacts, waiting (held before shared
    cells plus given way), makespan and waypoints given up."""
    scenarios = [
        Scenario(
            f"{world}-{robots}/{mode}", str(resolve_world(world)), robots, ("--deconfliction", mode)
        )
        for world, robots in STRESS_WORLDS
        if world in worlds
        for mode in modes
    ]
    result = run_fleets(scenarios, seeds, root)
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


def run_family(
    family: Sequence[FamilyMember], modes: Sequence[str], seeds: list[int], root: Path
) -> dict[str, Any]:
    """Whole fleets on the ``family`` members (their worlds written to ``root``/worlds) under
    each mode; the runs and each mode's figures and verdict, also kept in
    ``root``/family.json."""
    scenarios = [
        Scenario(
            f"{m.name}/{mode}",
            str(write_world(m, root / "worlds")),
            len(layout(m).starts),
            ("--deconfliction", mode),
        )
        for m in family
        for mode in modes
    ]
    result = run_fleets(scenarios, seeds, root)
    runs = [family_run(r) for r in result["runs"]]
    out = {"root": str(root), "runs": runs, "modes": family_summary(runs)}
    (root / "family.json").write_text(json.dumps(out, indent=2) + "\n")
    return out
