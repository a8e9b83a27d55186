"""``fleet bench coverage``: coverage quality and planning time on the built-in home and the
real apartment map, the boustrophedon planner against the old strip-and-lanes baseline
(planners/lanes.py) judged by the same metrics; and :func:`plan_summary`, a plan's figures as
`fleet plan coverage` and this bench report them."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from fleet.coordinator.planning import TourSpec
    from planners.robot import RobotSpec

APARTMENT = Path(__file__).resolve().parents[3] / "shared" / "data" / "maps"


def plan_summary(plan: Any) -> dict[str, Any]:
    """A coverage plan's figures, in total and per robot."""
    m = plan.metrics
    t = m.total
    return {
        "coverage": round(t.coverage, 5),
        "repetition": round(t.repetition, 5),
        "path_length_m": round(t.path_length_m, 3),
        "turns": t.turns,
        "est_time_s": round(sum(r.est_time_s for r in m.robots), 2),
        "makespan_s": round(m.makespan_s, 2),
        "plan_time_s": round(plan.plan_time_s, 4),
        "cleanable_area_m2": round(m.cleanable_area_m2, 3),
        "unreachable_free_m2": round(plan.unreachable_area_m2, 3),
        "robots": [
            {
                "id": i,
                "coverage": round(r.coverage, 5),
                "repetition": round(r.repetition, 5),
                "path_length_m": round(r.path_length_m, 3),
                "turns": r.turns,
                "est_time_s": round(r.est_time_s, 2),
            }
            for i, r in enumerate(m.robots)
        ],
    }


def bench_maps() -> tuple[list[tuple[str, Path]], list[Path]]:
    """The maps benched: the built-in home, and the apartment
    (../shared/data/maps/cob_ipa_apartment.yaml) when it is there; and the files missing."""
    from fleet.config import configs_dir

    maps = [("home", configs_dir() / "worlds" / "home.yaml")]
    apt = APARTMENT / "cob_ipa_apartment.yaml"
    if not apt.exists():
        return maps, [apt]
    return [*maps, ("apartment", apt)], []


def run_bench(
    maps: list[tuple[str, Path]],
    spec: TourSpec,
    robot: RobotSpec,
    repeat: int,
    status: Callable[[str], None],
) -> list[dict[str, Any]]:
    """The bench's rows, per map (:func:`bench_map`), telling ``status`` which case runs."""
    rows: list[dict[str, Any]] = []
    for name, path in maps:
        bench_map(name, path, spec, robot, repeat, rows, status)
    return rows


def bench_map(
    name: str,
    path: Path,
    spec: TourSpec,
    robot: RobotSpec,
    repeat: int,
    rows: list[dict[str, Any]],
    status: Callable[[str], None],
) -> None:
    """Append the bench rows of one map to ``rows``: 1 and 3 robots with the boustrophedon
    planner (the fastest of ``repeat`` plans timed), then the baseline lanes judged on the
    cleanable floor of the 1-robot plan; ``status`` is told which case runs."""
    from fleet.world import load_world
    from planners.coverage import plan_metrics
    from planners.lanes import plan_lanes

    world = load_world(path, robot.radius)
    grid = spec.grid(world)
    s1 = [p[:2] for p in world.start_poses(1, robot.radius)]
    s3 = [p[:2] for p in world.start_poses(3, robot.radius)]
    single = None
    for label, starts, case in (
        ("bcd k=1", s1, spec),
        ("bcd k=3", s3, spec),
    ):
        status(f"fleet bench coverage: {name}, {label}, run 1 of {repeat}")
        plan = case.plan(grid, starts, robot)
        fastest = plan.plan_time_s
        for run in range(2, repeat + 1):
            status(f"fleet bench coverage: {name}, {label}, run {run} of {repeat}")
            fastest = min(fastest, case.plan(grid, starts, robot).plan_time_s)
        row = {
            "map": name,
            "planner": label,
            **plan_summary(plan),
            "plan_time_s": round(fastest, 4),
        }
        row.pop("robots")
        row["free_m2"] = round(float(grid.free.sum()) * grid.resolution**2, 2)
        if label == "bcd k=1":
            single = plan
        if label == "bcd k=3" and single is not None:
            row["makespan_ratio_vs_k1"] = round(
                plan.metrics.makespan_s / single.metrics.makespan_s, 3
            )
        rows.append(row)
    for label, starts in (("baseline lanes k=1", s1), ("baseline lanes k=3", s3)):
        status(f"fleet bench coverage: {name}, {label}")
        dt = math.inf
        for _ in range(repeat):
            t0 = time.perf_counter()
            paths = plan_lanes(grid, starts, robot, spec.params.overlap)
            dt = min(dt, time.perf_counter() - t0)
        m = plan_metrics(
            grid,
            paths,
            spec.params,
            robot,
            wall_clearance=spec.wall_clearance,
            cleanable_mask=single.cleanable if single is not None else None,
        )
        rows.append(
            {
                "map": name,
                "planner": label,
                "coverage": round(m.total.coverage, 5),
                "repetition": round(m.total.repetition, 5),
                "path_length_m": round(m.total.path_length_m, 3),
                "turns": m.total.turns,
                "makespan_s": round(m.makespan_s, 2),
                "plan_time_s": round(dt, 4),
            }
        )
