"""``fleet plan coverage`` and ``fleet bench coverage``: coverage paths on any floor plan."""

from __future__ import annotations

import dataclasses
import json
import math
import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from fleet.cli.options import JsonOpt

if TYPE_CHECKING:
    from rich.status import Status

    from fleet.coordinator.planning import TourSpec
    from fleet.params import FleetConfig
    from planners.robot import RobotSpec

APARTMENT = Path(__file__).resolve().parents[3] / "shared" / "data" / "maps"

BareOpt = Annotated[
    bool,
    typer.Option(
        "--bare",
        help="Plan as the planner alone: 5 cm, coverage.overlap, the bare robot radius (the "
        "figures BENCHMARKS.md gave before the fleet's plan). Default: the coordinator's plan "
        "(2.5 cm, coordinator.lane_overlap, radius + coordinator.wall_clearance), the tour the "
        "fleet drives.",
    ),
]


def _spec(cfg: FleetConfig, bare: bool) -> TourSpec:
    """The plan to make: the coordinator's (the fleet drives it) or, with ``bare``, the
    planner's own defaults."""
    from fleet.coordinator.planning import bare_tour_spec, fleet_tour_spec

    return bare_tour_spec(cfg) if bare else fleet_tour_spec(cfg)


def _spec_text(spec: TourSpec) -> str:
    return (
        f"{100 * spec.resolution:g} cm, lane overlap {spec.params.overlap:g}, radius + "
        f"{100 * spec.wall_clearance:g} cm"
    )


def register(
    app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app: typer.Typer
) -> None:
    plan_app.command("coverage")(plan_coverage_cmd)
    bench_app.command("coverage")(bench_coverage)


def _fail(message: str, code: int = 2) -> None:
    typer.echo(f"error: {message}", err=True)
    raise typer.Exit(code)


def _status(text: str) -> Status:
    """A spinner with ``text`` on stderr while long work runs (shown on a terminal only, so
    stdout stays the table or the JSON)."""
    from rich.console import Console

    return Console(stderr=True).status(text)


def _parse_start(text: str) -> tuple[float, float]:
    parts = text.replace(" ", "").split(",")
    try:
        x, y = (float(p) for p in parts)
    except ValueError:
        _fail(f"--start {text!r}: expected X,Y in metres, e.g. --start 2.5,1.0")
    return x, y


def plan_coverage_cmd(
    map_path: Annotated[
        str,
        typer.Argument(
            metavar="MAP",
            help="A world YAML (configs/worlds/*.yaml, or the name of a built-in world: home, "
            "small) or a ROS map_server YAML (image, resolution, origin, thresholds).",
        ),
    ],
    robots: Annotated[
        int, typer.Option("--robots", "-k", min=1, help="Number of robots to split the work.")
    ] = 1,
    start: Annotated[
        list[str] | None,
        typer.Option(
            "--start",
            help="Start X,Y in metres (world frame), once per robot. Default: the world's "
            "start poses, else free spots near the dock or the most open point of the map.",
        ),
    ] = None,
    coverage_target: Annotated[
        float | None,
        typer.Option(
            min=0.0,
            max=1.0,
            help="Share of the cleanable floor to cover, 0-1 (with coverage.fill_in, the "
            "default): the fill-in passes stop there and a bcd plan drops what costs the most "
            "driving per cell above it, so a lower target gives a shorter path (1.0: every "
            "pass, nothing left). Default: coverage.fill_in_target in configs/fleet.yaml.",
        ),
    ] = None,
    resolution: Annotated[
        float | None,
        typer.Option(
            min=0.01, help="Grid cell size (m). Default: the plan's (2.5 cm; --bare 5 cm)."
        ),
    ] = None,
    bare: BareOpt = False,
    out: Annotated[
        Path, typer.Option(help="Directory for paths.json and plan.png (created if missing).")
    ] = Path("coverage_plan"),
    config: Annotated[
        Path | None, typer.Option(help="fleet.yaml to read (default: configs/fleet.yaml).")
    ] = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print the metrics as one JSON object.")
    ] = False,
) -> None:
    """Plan coverage paths on MAP and report coverage, repetition, length, turns and time.

    By default the plan is the coordinator's: the same function, grid (2.5 cm), lane overlap
    (coordinator.lane_overlap) and wall clearance (coordinator.wall_clearance), so with one
    robot from the dock it is the tour the fleet cuts into tasks and drives; --bare plans as
    the planner alone. Rooms are segmented, each swept in the direction of its dominant walls
    (boustrophedon cell decomposition, Choset 2000); with several robots the work is split to
    minimize the makespan.
    Writes DIR/paths.json (world metres) and DIR/plan.png (regions coloured, paths drawn, free
    space no robot can clean hatched red), and prints the table per robot and in total.

    Examples:

      fleet plan coverage home --robots 3

      fleet plan coverage ../shared/data/maps/cob_ipa_apartment.yaml --json

      fleet plan coverage configs/worlds/small.yaml --start 0.6,0.85 --out /tmp/small

      fleet plan coverage home --coverage-target 0.98
    """
    from fleet.config import ConfigError, resolve_world
    from fleet.params import load_fleet_config
    from fleet.world import load_world
    from planners.coverage import PlanningError
    from planners.coverage.render import render_plan

    try:
        cfg = load_fleet_config(config)
        path = resolve_world(map_path)
        world = load_world(path, cfg.robot.radius)
    except ConfigError as err:
        _fail(str(err))
    spec = _spec(cfg, bare)
    if resolution is not None:
        spec = dataclasses.replace(spec, resolution=resolution)
    try:
        grid = spec.grid(world)
    except ConfigError as err:
        _fail(str(err))
    params, robot = spec.params, cfg.robot
    if coverage_target is not None:
        params = dataclasses.replace(params, fill_in_target=coverage_target)
    spec = dataclasses.replace(spec, params=params)
    if start:
        starts = [_parse_start(s) for s in start]
        if robots not in (1, len(starts)):
            _fail(f"--robots {robots} but {len(starts)} --start given: give one start per robot")
        robots = len(starts)
    else:
        try:
            starts = [p[:2] for p in world.start_poses(robots, cfg.robot.radius)]
        except ConfigError as err:
            _fail(str(err))
    try:
        with _status(f"planning coverage of {path.name} for {robots} robot(s)"):
            plan = spec.plan(grid, starts, robot)
    except PlanningError as err:
        _fail(f"{path}: {err}")
    out.mkdir(parents=True, exist_ok=True)
    doc = {
        "frame": "world",
        "robots": [
            {"id": i, "start": [float(s[0]), float(s[1])], "path": p.round(4).tolist()}
            for i, (s, p) in enumerate(zip(plan.starts, plan.paths, strict=True))
        ],
        "cleaning_width_m": robot.cleaning_width,
        "robot_radius_m": robot.radius,
    }
    (out / "paths.json").write_text(json.dumps(doc))
    render_plan(grid, plan.room_labels, list(plan.paths), plan.unreachable).save(out / "plan.png")
    summary = _summary(plan)
    summary["map"] = str(path)
    summary["plan"] = {**spec.to_json(), "bare": bare}
    summary["files"] = {"paths": str(out / "paths.json"), "plan": str(out / "plan.png")}
    if as_json:
        print(json.dumps(summary))
        return
    which = "the planner alone" if bare else "the fleet's plan"
    _print_table(
        plan,
        f"Coverage of {path.name}: {robots} robot(s); {which} ({_spec_text(spec)})",
    )
    from rich.console import Console

    console = Console()
    console.print(
        f"cleanable area {summary['cleanable_area_m2']:.2f} m², "
        f"{plan.room_labels.max()} rooms, {plan.cell_labels.max()} cells, "
        f"planned in {summary['plan_time_s']:.2f} s"
    )
    console.print(
        f"unreachable free space: {summary['unreachable_free_m2']:.2f} m² "
        f"(free cells no robot can clean from these starts: cut off, or too close to walls "
        f"for the {robot.cleaning_width:.2f} m swath), hatched red in plan.png"
    )
    console.print(f"wrote {out / 'paths.json'} and {out / 'plan.png'}")


def _summary(plan: Any) -> dict[str, Any]:
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


def _print_table(plan: Any, title: str) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=title)
    for col in ("robot", "coverage", "repetition", "length (m)", "turns", "est. time (s)"):
        table.add_column(col, justify="right")
    m = plan.metrics
    for i, r in enumerate(m.robots):
        table.add_row(
            str(i),
            f"{100 * r.coverage:.2f} %",
            f"{100 * r.repetition:.1f} %",
            f"{r.path_length_m:.1f}",
            str(r.turns),
            f"{r.est_time_s:.0f}",
        )
    t = m.total
    table.add_row(
        "total",
        f"{100 * t.coverage:.2f} %",
        f"{100 * t.repetition:.1f} %",
        f"{t.path_length_m:.1f}",
        str(t.turns),
        f"makespan {m.makespan_s:.0f}",
        style="bold",
    )
    Console().print(table)


def bench_coverage(
    as_json: JsonOpt = False,
    repeat: Annotated[
        int,
        typer.Option(
            "--repeat",
            min=1,
            help="Plan every case this many times and report the fastest planning time (the "
            "plans are the same each time; on a shared machine the fastest run is the least "
            "disturbed one; single runs vary by up to 1.6x there). 1 for a quick look.",
        ),
    ] = 3,
    bare: BareOpt = False,
) -> None:
    """Coverage quality and planning time on the built-in home and the real apartment map.

    Every plan is made as the coordinator makes its tour (2.5 cm, coordinator.lane_overlap,
    radius + coordinator.wall_clearance; --bare: the planner alone at 5 cm). For each map: 1
    robot and 3 robots with the boustrophedon planner, and as the baseline the old
    strip-and-lanes planner (planners/lanes.py) judged by the same metrics. Reports coverage
    of the cleanable area, repetition, length, turns, the makespan ratio of 3 robots to 1, and
    planning time (wall clock, the fastest of --repeat runs; the machine may be shared). The
    apartment (../shared/data/maps/cob_ipa_apartment.yaml) is skipped if absent.
    """
    from fleet.config import configs_dir
    from fleet.params import load_fleet_config

    cfg = load_fleet_config()
    spec, robot = _spec(cfg, bare), cfg.robot
    maps = [("home", configs_dir() / "worlds" / "home.yaml")]
    apt = APARTMENT / "cob_ipa_apartment.yaml"
    if apt.exists():
        maps.append(("apartment", apt))
    else:
        typer.echo(f"note: {apt} not found; the apartment is left out", err=True)
    rows: list[dict[str, Any]] = []
    with _status("fleet bench coverage") as status:
        for name, path in maps:
            _bench_map(name, path, spec, robot, repeat, rows, status)
    if as_json:
        print(json.dumps({"plan": {**spec.to_json(), "bare": bare}, "results": rows}))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(
        title=f"fleet bench coverage (cleaning width {robot.cleaning_width:.2f} m, "
        f"robot radius {robot.radius:.2f} m; {_spec_text(spec)})"
    )
    cols = (
        "map",
        "planner",
        "coverage",
        "repetition",
        "length (m)",
        "turns",
        "makespan (s)",
        "k3/k1",
        "plan (s)",
    )
    for c in cols:
        table.add_column(c, justify="right")
    for r in rows:
        table.add_row(
            r["map"],
            r["planner"],
            f"{100 * r['coverage']:.2f} %",
            f"{100 * r['repetition']:.1f} %",
            f"{r['path_length_m']:.1f}",
            str(r["turns"]),
            f"{r['makespan_s']:.0f}",
            str(r.get("makespan_ratio_vs_k1", "")),
            f"{r['plan_time_s']:.2f}",
        )
    console = Console()
    if console.width < 120:
        console = Console(width=120)
    console.print(table)


def _bench_map(
    name: str,
    path: Path,
    spec: TourSpec,
    robot: RobotSpec,
    repeat: int,
    rows: list[dict[str, Any]],
    status: Status,
) -> None:
    """Append the bench rows of one map to ``rows``, telling ``status`` which case runs."""
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
        status.update(f"fleet bench coverage: {name}, {label}, run 1 of {repeat}")
        plan = case.plan(grid, starts, robot)
        fastest = plan.plan_time_s
        for run in range(2, repeat + 1):
            status.update(f"fleet bench coverage: {name}, {label}, run {run} of {repeat}")
            fastest = min(fastest, case.plan(grid, starts, robot).plan_time_s)
        row = {
            "map": name,
            "planner": label,
            **_summary(plan),
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
        status.update(f"fleet bench coverage: {name}, {label}")
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
