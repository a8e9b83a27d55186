"""`fleet bench explore`: exploring a home with N robots against one robot alone, and cleaning
planned on the map they made against cleaning planned on the world file.

Per seed, four whole runs, each in its own run dir under the bench's root:

1. ``fleet explore`` with N robots (``explore-N-seedS``): sim time to finish, path length
   driven, and the merged map against the true floor (explore.json: free-space IoU, and the
   share of true walls with a mapped wall within 5 cm, ``fleet.report.exploration``);
2. ``fleet explore`` with one robot on the same seed (``explore-1-seedS``): the time and path
   the fleet is measured against (``time_ratio``: N robots' sim time over one robot's);
3. ``fleet up --map`` on the map run 1 wrote (``clean-map-seedS``): the cleaning planned on the
   explored map, the simulator running the true world;
4. ``fleet up`` on the world file (``clean-world-seedS``), the same fleet and seed:
   ``coverage_gap_points`` is 100 × (coverage on the map − coverage on the world file).

The targets (issue 27, home, 3 robots): ``time_ratio`` ≤ 0.5, IoU ≥ 0.95, walls within 5 cm
≥ 0.95, coverage gap ≥ −1 point, 0 contacts on the explored map; :func:`verdict` judges them
on the worst seed.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fleet.supervisor.runner import RunningFleet

TARGETS = {
    "time_ratio_max": 0.5,
    "free_iou_min": 0.95,
    "walls_within_min": 0.95,
    "coverage_gap_points_min": -1.0,
    "contacts_max": 0,
}
EXPLORE_REPORT = "explore.json"
MAP_YAML = "map.yaml"


def _run(
    run_dir: Path,
    world: str,
    robots: int,
    seed: int,
    speed: float,
    timeout_s: float,
    command: tuple[str, ...] = ("up",),
    options: tuple[str, ...] = (),
) -> RunningFleet:
    fleet = RunningFleet(
        run_dir,
        world,
        robots,
        seed,
        timeout_s=timeout_s,
        speed=speed,
        options=options,
        command=command,
    )
    try:
        fleet.finish(timeout=timeout_s + 120.0)
    finally:
        fleet.cleanup()
    return fleet


def exploration_figures(run_dir: Path) -> dict[str, Any]:
    """What one ``fleet explore`` run took and made (from its explore.json)."""
    path = run_dir / EXPLORE_REPORT
    if not path.exists():
        return {"status": "no report", "run_dir": str(run_dir)}
    report = json.loads(path.read_text())
    lengths = report["path_length_m"]
    return {
        "status": report["status"],
        "sim_s": report["sim_s"],
        "wall_s": report["wall_s"],
        "path_length_m": round(sum(lengths.values()), 2),
        "path_length_per_robot_m": lengths,
        "free_iou": report["free_iou"],
        "walls_within": report.get("walls_within"),
        "plan_floor": report.get("plan_floor"),
        "run_dir": str(run_dir),
    }


def cleaning_figures(report: dict[str, Any] | None, run_dir: Path) -> dict[str, Any]:
    """What one ``fleet up`` run cleaned (from its report.json)."""
    if report is None:
        return {"status": "no report", "run_dir": str(run_dir)}
    contacts = report["collisions"]
    return {
        "status": report["status"],
        "coverage": report["coverage"],
        "repetition": report["repetition"],
        "makespan_s": report["makespan_s"],
        "contacts": contacts["robot_wall"] + contacts["robot_robot"],
        "floor": (report.get("plan") or {}).get("floor"),
        "run_dir": str(run_dir),
    }


def seed_figures(
    team: dict[str, Any], alone: dict[str, Any], on_map: dict[str, Any], on_world: dict[str, Any]
) -> dict[str, Any]:
    """One seed's comparison: N robots' exploration against one robot's, and the cleaning on
    the explored map against the cleaning on the world file."""
    out: dict[str, Any] = {"explore": team, "explore_alone": alone}
    out["clean_on_map"], out["clean_on_world"] = on_map, on_world
    if team.get("sim_s") and alone.get("sim_s"):
        out["time_ratio"] = round(team["sim_s"] / alone["sim_s"], 3)
        out["path_ratio"] = round(team["path_length_m"] / max(alone["path_length_m"], 1e-9), 3)
    if "coverage" in on_map and "coverage" in on_world:
        out["coverage_gap_points"] = round(100 * (on_map["coverage"] - on_world["coverage"]), 2)
    return out


def verdict(seeds: list[dict[str, Any]]) -> dict[str, Any]:
    """Each target judged on the worst seed (None where a seed lacks the figure)."""

    def worst(pick: Callable[[dict[str, Any]], Any], fn: Callable) -> Any:
        values = [pick(s) for s in seeds]
        return None if not values or any(v is None for v in values) else fn(values)

    ratio = worst(lambda s: s.get("time_ratio"), max)
    iou = worst(lambda s: s["explore"].get("free_iou"), min)
    walls = worst(lambda s: s["explore"].get("walls_within"), min)
    gap = worst(lambda s: s.get("coverage_gap_points"), min)
    contacts = worst(lambda s: s["clean_on_map"].get("contacts"), max)
    t = TARGETS
    return {
        "time_ratio_worst": ratio,
        "free_iou_worst": iou,
        "walls_within_worst": walls,
        "coverage_gap_points_worst": gap,
        "contacts_on_map_worst": contacts,
        "met": {
            "time_ratio": ratio is not None and ratio <= t["time_ratio_max"],
            "free_iou": iou is not None and iou >= t["free_iou_min"],
            "walls_within": walls is not None and walls >= t["walls_within_min"],
            "coverage_gap": gap is not None and gap >= t["coverage_gap_points_min"],
            "contacts": contacts is not None and contacts <= t["contacts_max"],
        },
    }


def run_bench(
    root: Path,
    world: str,
    robots: int,
    seeds: list[int],
    speed: float,
    timeout_s: float,
    progress: Callable[[str], None],
) -> dict[str, Any]:
    """The four runs of every seed (module docstring); the result is also written to
    ``root / bench.json`` after every seed."""
    root.mkdir(parents=True, exist_ok=True)
    result: dict[str, Any] = {
        "world": world,
        "robots": robots,
        "speed": speed,
        "targets": TARGETS,
        "seeds": {},
    }
    for seed in seeds:
        team_dir = root / f"explore-{robots}-seed{seed}"
        progress(f"seed {seed}: exploring with {robots} robots …")
        _run(team_dir, world, robots, seed, speed, timeout_s, ("explore",))
        team = exploration_figures(team_dir)
        progress(f"    {team}")
        alone_dir = root / f"explore-1-seed{seed}"
        progress(f"seed {seed}: exploring with one robot …")
        _run(alone_dir, world, 1, seed, speed, timeout_s, ("explore",))
        alone = exploration_figures(alone_dir)
        progress(f"    {alone}")
        on_map: dict[str, Any] = {"status": "no map"}
        if (team_dir / MAP_YAML).exists():
            progress(f"seed {seed}: cleaning on the explored map …")
            map_dir = root / f"clean-map-seed{seed}"
            fleet = _run(
                map_dir,
                world,
                robots,
                seed,
                speed,
                timeout_s,
                options=("--map", str(team_dir / MAP_YAML)),
            )
            on_map = cleaning_figures(_report(map_dir), map_dir)
            progress(
                f"    {on_map}"
                + ("" if fleet.proc.returncode == 0 else f" (exit {fleet.proc.returncode})")
            )
        progress(f"seed {seed}: cleaning on the world file …")
        world_dir = root / f"clean-world-seed{seed}"
        _run(world_dir, world, robots, seed, speed, timeout_s)
        on_world = cleaning_figures(_report(world_dir), world_dir)
        progress(f"    {on_world}")
        result["seeds"][str(seed)] = seed_figures(team, alone, on_map, on_world)
        result["verdict"] = verdict(list(result["seeds"].values()))
        (root / "bench.json").write_text(json.dumps(result, indent=2) + "\n")
    return result


def _report(run_dir: Path) -> dict[str, Any] | None:
    path = run_dir / "report.json"
    return json.loads(path.read_text()) if path.exists() else None


def table_lines(result: dict[str, Any]) -> list[str]:
    """One line per seed and the verdict."""
    lines = []
    for seed, s in result["seeds"].items():
        team, alone = s["explore"], s["explore_alone"]
        on_map, on_world = s["clean_on_map"], s["clean_on_world"]
        lines.append(
            f"seed {seed}: explored in {team.get('sim_s')} s sim ({alone.get('sim_s')} s alone, "
            f"×{s.get('time_ratio')}), path {team.get('path_length_m')} m "
            f"({alone.get('path_length_m')} m alone), IoU {team.get('free_iou')}, walls within "
            f"5 cm {team.get('walls_within')}; coverage on the map {on_map.get('coverage')} "
            f"against {on_world.get('coverage')} on the world file "
            f"({s.get('coverage_gap_points')} points), contacts {on_map.get('contacts')}"
            + _lost_words(team.get("plan_floor"))
        )
    v = result.get("verdict") or {}
    met = v.get("met") or {}
    lines.append(
        "targets met: " + ", ".join(f"{k} {'yes' if ok else 'NO'}" for k, ok in met.items())
    )
    return lines


def _lost_words(lost: dict[str, float] | None) -> str:
    """The floor a plan on the map loses, by cause, in words ("" for a run without it)."""
    if not lost:
        return ""
    return (
        f"; the map's plan loses {lost['lost_m2']} m² of {lost['brushable_m2']} m² brushable: "
        f"{lost['walls_on_floor_m2']} m² to walls drawn onto the floor, "
        f"{lost['unknown_on_floor_m2']} m² to floor left unknown"
    )
