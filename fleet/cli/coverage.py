"""``fleet plan coverage`` and ``fleet bench coverage``: coverage paths on any floor plan (the
bench's runner in fleet.bench.coverage)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from fleet.cli.options import JsonOpt

if TYPE_CHECKING:
    from rich.status import Status

    from fleet.coordinator.planning import TourSpec
    from fleet.params import FleetConfig
    from fleet.world import World
    from planners.grid import GridMap
    from planners.robot import RobotSpec

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
MapArg = Annotated[
    str,
    typer.Argument(
        metavar="MAP",
        help="A world YAML (configs/worlds/*.yaml, or the name of a built-in world: home, "
        "small) or a ROS map_server YAML (image, resolution, origin, thresholds).",
    ),
]
StartsOpt = Annotated[
    list[str] | None,
    typer.Option(
        "--start",
        help="Start X,Y in metres (world frame), once per robot. Default: the world's "
        "start poses, else free spots near the dock or the most open point of the map.",
    ),
]
CoverageTargetOpt = Annotated[
    float | None,
    typer.Option(
        min=0.0,
        max=1.0,
        help="Share of the cleanable floor to cover, 0-1 (with coverage.fill_in, the "
        "default): the fill-in passes stop there and a bcd plan drops what costs the most "
        "driving per cell above it, so a lower target gives a shorter path (1.0: every "
        "pass, nothing left). Default: coverage.fill_in_target in configs/fleet.yaml.",
    ),
]
ResolutionOpt = Annotated[
    float | None,
    typer.Option(min=0.01, help="Grid cell size (m). Default: the plan's (2.5 cm; --bare 5 cm)."),
]
RepeatOpt = Annotated[
    int,
    typer.Option(
        "--repeat",
        min=1,
        help="Plan every case this many times and report the fastest planning time (the "
        "plans are the same each time; on a shared machine the fastest run is the least "
        "disturbed one; single runs vary by up to 1.6x there). 1 for a quick look.",
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
    map_path: MapArg,
    robots: Annotated[
        int, typer.Option("--robots", "-k", min=1, help="Number of robots to split the work.")
    ] = 1,
    start: StartsOpt = None,
    coverage_target: CoverageTargetOpt = None,
    resolution: ResolutionOpt = None,
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
    from fleet.bench.coverage import plan_summary
    from planners.coverage import PlanningError

    cfg, path, world = _read_map(map_path, config)
    spec, grid = _plan_spec(cfg, world, bare, resolution, coverage_target)
    starts = _starts(start, robots, world, cfg)
    robots = len(starts)
    try:
        with _status(f"planning coverage of {path.name} for {robots} robot(s)"):
            plan = spec.plan(grid, starts, cfg.robot)
    except PlanningError as err:
        _fail(f"{path}: {err}")
    summary = plan_summary(plan)
    summary["map"] = str(path)
    summary["plan"] = {**spec.to_json(), "bare": bare}
    summary["files"] = _write_plan(out, plan, grid, cfg.robot)
    if as_json:
        print(json.dumps(summary))
        return
    which = "the planner alone" if bare else "the fleet's plan"
    _print_table(
        plan,
        f"Coverage of {path.name}: {robots} robot(s); {which} ({_spec_text(spec)})",
    )
    _print_plan_notes(plan, summary, cfg.robot, out)


def _read_map(map_path: str, config: Path | None) -> tuple[FleetConfig, Path, World]:
    """The parameters, and MAP's file and world; exits naming what does not load."""
    from fleet.config import ConfigError, resolve_world
    from fleet.params import load_fleet_config
    from fleet.world import load_world

    try:
        cfg = load_fleet_config(config)
        path = resolve_world(map_path)
        world = load_world(path, cfg.robot.radius)
    except ConfigError as err:
        _fail(str(err))
    return cfg, path, world


def _plan_spec(
    cfg: FleetConfig,
    world: World,
    bare: bool,
    resolution: float | None,
    coverage_target: float | None,
) -> tuple[TourSpec, GridMap]:
    """The plan to make (:func:`_spec`, at ``resolution`` and to ``coverage_target`` if
    given) and its grid of ``world``."""
    from fleet.config import ConfigError

    spec = _spec(cfg, bare)
    if resolution is not None:
        spec = dataclasses.replace(spec, resolution=resolution)
    try:
        grid = spec.grid(world)
    except ConfigError as err:
        _fail(str(err))
    if coverage_target is not None:
        params = dataclasses.replace(spec.params, fill_in_target=coverage_target)
        spec = dataclasses.replace(spec, params=params)
    return spec, grid


def _starts(
    start: list[str] | None, robots: int, world: World, cfg: FleetConfig
) -> list[tuple[float, float]]:
    """The robots' starts: one per --start, else the world's first ``robots`` start poses."""
    from fleet.config import ConfigError

    if start:
        starts = [_parse_start(s) for s in start]
        if robots not in (1, len(starts)):
            _fail(f"--robots {robots} but {len(starts)} --start given: give one start per robot")
        return starts
    try:
        poses = world.start_poses(robots, cfg.robot.radius)
    except ConfigError as err:
        _fail(str(err))
    return [p[:2] for p in poses]


def _write_plan(out: Path, plan: Any, grid: GridMap, robot: RobotSpec) -> dict[str, str]:
    """DIR/paths.json (world metres) and DIR/plan.png; their paths."""
    from planners.coverage.render import render_plan

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
    return {"paths": str(out / "paths.json"), "plan": str(out / "plan.png")}


def _print_plan_notes(plan: Any, summary: dict[str, Any], robot: RobotSpec, out: Path) -> None:
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
    repeat: RepeatOpt = 3,
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
    from fleet.bench.coverage import bench_maps, run_bench
    from fleet.params import load_fleet_config

    cfg = load_fleet_config()
    spec, robot = _spec(cfg, bare), cfg.robot
    maps, missing = bench_maps()
    for path in missing:
        typer.echo(f"note: {path} not found; the apartment is left out", err=True)
    with _status("fleet bench coverage") as status:
        rows = run_bench(maps, spec, robot, repeat, status.update)
    if as_json:
        print(json.dumps({"plan": {**spec.to_json(), "bare": bare}, "results": rows}))
        return
    _print_bench(rows, spec, robot)


def _print_bench(rows: list[dict[str, Any]], spec: TourSpec, robot: RobotSpec) -> None:
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
