"""``fleet slam replay``: run the agents' SLAM offline on a CARMEN log and write its results;
``fleet bench slam``: SLAM accuracy and speed on a simulated route (driver in fleet.bench.slam)."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

import typer

from fleet.cli.common import parse_seeds
from fleet.cli.options import JsonOpt


def register(
    app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app: typer.Typer
) -> None:
    slam_app.command("replay")(replay)
    bench_app.command("slam")(bench_slam)


def replay(
    log: Annotated[
        Path,
        typer.Argument(
            help="CARMEN log (FLASER / ROBOTLASER1 / ODOM lines; .gz is read transparently)."
        ),
    ],
    out: Annotated[
        Path,
        typer.Option(help="Directory for map.png, map.yaml, trajectory.csv and timing.json."),
    ] = Path("slam-replay"),
    config: Annotated[
        Path | None,
        typer.Option(help="fleet.yaml whose `slam:` section to use (default: the built-in one)."),
    ] = None,
    range_min: Annotated[
        float, typer.Option(help="Shorter returns are treated as no return (metres).")
    ] = 0.05,
    as_json: JsonOpt = False,
) -> None:
    """Replay a recorded CARMEN log through the same SLAM the agents run.

    Writes, into --out: map.png (ROS map_server colours: black occupied, white free, grey
    unknown; with map.yaml beside it), trajectory.csv (header t,x,y,theta: the pose after each
    scan, as corrected by the final loop-closure optimization), live.csv (the same, as SLAM
    gave it at each scan) and timing.json (milliseconds per scan, replay speed as a multiple
    of real time, loop closures).

    When LOG.truth.csv lies beside the log (`fleet sim --record-carmen` writes it), both
    trajectories and the log's odometry are scored against it: RPE over 1, 5 and 20 scans
    (Kümmerle et al. 2009) and ATE after a rigid alignment; the headline is the live one.

    Example: fleet slam replay intel.gfs.log.gz --out /tmp/intel
    """
    from agents.slam.replay import replay_log
    from fleet.bench.slam_outputs import score_against_truth, write_replay_outputs
    from fleet.carmen import CarmenParseError, read_log
    from fleet.config import ConfigError
    from fleet.params import load_fleet_config
    from sim_server.recorder import truth_path_for

    try:
        params = load_fleet_config(config).slam
        parsed = read_log(log)
        result = replay_log(parsed, params, range_min=range_min)
    except (CarmenParseError, ConfigError) as e:
        typer.echo(f"error: {e}", err=True)
        raise typer.Exit(2) from None
    except ValueError as e:
        typer.echo(f"error: {log}: {e}", err=True)
        raise typer.Exit(2) from None
    summary = write_replay_outputs(result, parsed, out, params, log)
    truth_file = truth_path_for(log)
    if truth_file.exists():
        try:
            summary.update(score_against_truth(result, parsed, truth_file))
        except ValueError as e:
            typer.echo(f"error: {e}", err=True)
            raise typer.Exit(2) from None
        (out / "timing.json").write_text(json.dumps(summary, indent=2) + "\n")
    if as_json:
        typer.echo(json.dumps(summary))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"SLAM replay of {log.name}")
    table.add_column("metric")
    table.add_column("value", justify="right")
    for key, value in summary.items():
        table.add_row(key, f"{value:.3f}" if isinstance(value, float) else str(value))
    Console().print(table)


# The targets: (key, bound, "max" when the value must not exceed it, else "min").
BENCH_TARGETS = {
    "ate_rmse_m": (0.05, "max"),
    "odom_ate_rmse_m": (0.5, "min"),
    "ms_per_scan_median": (10.0, "max"),
    "replay_speedup": (20.0, "min"),
}


OdomNoiseScaleOpt = Annotated[
    float | None,
    typer.Option(
        help="Multiply every odometry noise term of fleet.yaml (alphas, heading bias) by this "
        "for the drive. Default 5: with fleet.yaml's gentle drift alone, raw odometry on the "
        "home route ends at about 0.2 m ATE, too little to show what SLAM corrects; 5× "
        "gives 0.6–1.1 m (seeds 0–2)."
    ),
]
BenchOutOpt = Annotated[
    Path | None,
    typer.Option(
        help="Keep the recording here: slam.log (CARMEN), slam.log.truth.csv, map.png, "
        "map.yaml, trajectory.csv, timing.json, bench.json. Default: a temporary directory."
    ),
]
LogOpt = Annotated[
    Path | None,
    typer.Option(
        help="Benchmark on this real CARMEN log instead of a simulated route: odometry "
        "made from the log's reference poses with noise (data/slam/README.md recipe), "
        "SLAM scored against the reference. Writes map.png per seed into --out "
        "(default slam-bench/)."
    ),
]
ShiftOpt = Annotated[
    float,
    typer.Option(
        help="Move the world by this many metres along x and y before driving (e.g. 0.025: "
        "walls on cell borders of a lattice on round numbers, as real walls are off any "
        "lattice; the SLAM must put its lattice on them; 0 keeps the world's own "
        "coordinates, where home.yaml's walls sit on round numbers)."
    ),
]


def bench_slam(
    seconds: Annotated[
        float, typer.Option("--seconds", "-s", help="Sim seconds of driving (the route length).")
    ] = 600.0,
    seed: Annotated[int, typer.Option(help="Seed for lidar and odometry noise.")] = 0,
    world: Annotated[
        str, typer.Option("--world", "-w", help="World YAML or built-in world name.")
    ] = "home",
    odom_noise_scale: OdomNoiseScaleOpt = None,
    out: BenchOutOpt = None,
    config: Annotated[
        Path | None, typer.Option(help="fleet.yaml to use (default: the built-in one).")
    ] = None,
    as_json: JsonOpt = False,
    log: LogOpt = None,
    seeds: Annotated[
        str, typer.Option(help="With --log: noise seeds, 0,1,2 or 0-4 or a mix.")
    ] = "0,1,2",
    shift: ShiftOpt = 0.0,
    every: Annotated[
        int,
        typer.Option(
            min=1,
            help="With --log: keep one scan in this many, odometry made between the kept "
            "ones (a sparse log: Freiburg 079's scans are 0.1 m apart, --every 9 makes 0.9 m).",
        ),
    ] = 1,
) -> None:
    """Drive one simulated robot around every room of a world, then score SLAM against truth;
    with --log, score SLAM on a real robot's log against the log's reference trajectory.

    The route visits the most open point of each room and returns to the start, lap after lap
    (every second lap reversed), for --seconds of sim time; a scripted controller steers on the
    true pose. Scans and the simulator's drifting odometry are recorded as a CARMEN log and
    replayed through the agents' SLAM (`fleet slam replay` does the same on any log).

    Prints: ate_rmse_m (SLAM vs truth, no alignment: the SLAM map frame is the start pose),
    odom_ate_rmse_m (raw odometry vs truth), rpe_trans_m / rpe_rot_deg (Kümmerle et al. 2009
    relative pose error, mean over every pose paired with the pose 1 s later; rpe_1m_* pairs
    poses 1 m of travel apart), ms_per_scan_median / _p95 and replay_speedup (log duration over
    SLAM processing time, wall clock; replay_speedup_cpu over process CPU time). Targets:
    ATE ≤ 0.05 m while odometry drifts ≥ 0.5 m, ≤ 10 ms per scan median, replay ≥ 20×.

    With --log LOG: for each of --seeds, noisy odometry from the log's reference poses, SLAM
    replayed on it, and RPE over 1, 5 and 20 scans (Kümmerle et al. 2009) and aligned ATE for
    the live SLAM estimate (headline: what the robot drives on), the final optimised
    trajectory and the noisy odometry; per-scan time median / p95 / max. Targets (mean over
    seeds): RPE over 20 scans ≤ 0.10 m, ATE ≤ 0.30 m, ≤ 10 ms median and ≤ 15 ms p95 per scan.

    Example: fleet bench slam --seconds 120 --out /tmp/slam-bench
    Example: fleet bench slam --shift 0.025   # the home's walls off round coordinates
    Example: fleet bench slam --log aces-corrected.log.gz --seeds 0,1,2 --out /tmp/aces
    Example: fleet bench slam --log freiburg-079-corrected.log.gz --every 9   # sparse scans
    """
    if log is not None:
        _bench_log(log, seeds, out or Path("slam-bench"), config, as_json, every)
        return

    from fleet.bench.slam import DEFAULT_ODOM_NOISE_SCALE, bench_route

    scale = DEFAULT_ODOM_NOISE_SCALE if odom_noise_scale is None else odom_noise_scale
    if seconds < 5 or scale < 0:
        typer.echo("error: need --seconds >= 5 and --odom-noise-scale >= 0", err=True)
        raise typer.Exit(2)
    cfg, w = _route_world(config, world, shift)
    try:
        with _route_progress(seconds) as progress:
            summary = bench_route(w, cfg, seconds, seed, scale, out, shift, progress)
    except ValueError as e:
        typer.echo(f"error: {e}", err=True)
        raise typer.Exit(2) from None
    if as_json:
        typer.echo(json.dumps(summary))
        return
    _print_route_bench(summary, w.name)


def _print_route_bench(summary: dict[str, Any], world: str) -> None:
    """The route's figures, each against its target (BENCH_TARGETS) if it has one."""
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"SLAM on a {summary['route_seconds']:.0f} s route through {world}")
    table.add_column("metric")
    table.add_column("value", justify="right")
    table.add_column("target")
    for key, value in summary.items():
        bound = BENCH_TARGETS.get(key)
        goal = ""
        if bound is not None:
            ok = value <= bound[0] if bound[1] == "max" else value >= bound[0]
            goal = f"{'≤' if bound[1] == 'max' else '≥'} {bound[0]:g} {'met' if ok else 'MISSED'}"
        table.add_row(key, f"{value:.4g}" if isinstance(value, float) else str(value), goal)
    Console().print(table)


def _route_world(config: Path | None, world: str, shift: float) -> tuple[Any, Any]:
    """The parameters and the world to drive, moved by ``shift`` along x and y; exits naming
    what does not load."""
    from fleet.config import ConfigError, resolve_world
    from fleet.params import load_fleet_config
    from fleet.world import load_world, shift_world

    try:
        cfg = load_fleet_config(config)
        w = load_world(resolve_world(world), cfg.robot.radius)
        if shift:
            w = shift_world(w, shift, shift)
    except ConfigError as e:
        typer.echo(f"error: {e}", err=True)
        raise typer.Exit(2) from None
    return cfg, w


def _bench_log(
    log: Path, seeds: str, out: Path, config: Path | None, as_json: bool, every: int = 1
) -> None:
    """``fleet bench slam --log``: run :func:`fleet.bench.slam_log.bench_log` with a progress
    bar per seed on stderr, then print JSON or the tables."""
    from fleet.bench.slam_log import bench_log
    from fleet.carmen import CarmenParseError
    from fleet.config import ConfigError
    from fleet.params import load_fleet_config

    seed_list = parse_seeds(seeds)
    try:
        cfg = load_fleet_config(config)
        with _log_progress(log) as progress:
            summary = bench_log(log, cfg, seed_list, out, progress, every)
    except (CarmenParseError, ConfigError) as e:
        typer.echo(f"error: {e}", err=True)
        raise typer.Exit(2) from None
    except ValueError as e:
        typer.echo(f"error: {log}: {e}", err=True)
        raise typer.Exit(2) from None
    if as_json:
        typer.echo(json.dumps(summary))
        return
    _print_log_bench(summary, log, seeds)


def _print_log_bench(summary: dict[str, Any], log: Path, seeds: str) -> None:
    """The errors of each seed's trajectories, the per-scan times, and the targets."""
    from rich.console import Console
    from rich.table import Table

    from fleet.bench.slam_log import LOG_TARGETS

    table = Table(
        title=f"SLAM on {log.name}: {summary['scans']} scans, {summary['beams']} beams over "
        f"{summary['fov_deg']:.0f}°, seeds {seeds} (RPE/ATE in m)"
    )
    for column in ("seed", "trajectory", "RPE 1", "RPE 5", "RPE 20", "ATE"):
        table.add_column(column, justify="right")
    rows = [*summary["runs"], {"seed": "mean", **summary["mean"]}]
    for run in rows:
        for label, prefix in (("SLAM live", ""), ("SLAM final", "final_"), ("odometry", "odom_")):
            table.add_row(
                str(run["seed"]),
                label,
                *(
                    f"{run.get(f'{prefix}{k}', float('nan')):.3f}"
                    for k in ("rpe1_m", "rpe5_m", "rpe20_m", "ate_m")
                ),
            )
    Console().print(table)
    timing = Table(title="per-scan time (ms, wall clock / process CPU) and loop closures")
    for column in ("seed", "median", "p95", "max", "loop closures", "map"):
        timing.add_column(column, justify="right")
    for run in summary["runs"]:
        timing.add_row(
            str(run["seed"]),
            f"{run['ms_per_scan_median']:.2f} / {run['cpu_ms_per_scan_median']:.2f}",
            f"{run['ms_per_scan_p95']:.2f} / {run['cpu_ms_per_scan_p95']:.2f}",
            f"{run['ms_per_scan_max']:.1f} / {run['cpu_ms_per_scan_max']:.1f}",
            str(run["loop_closures"]),
            run["map_png"],
        )
    Console().print(timing)
    mean = summary["mean"]
    for key, (bound, kind) in LOG_TARGETS.items():
        ok = mean[key] <= bound if kind == "max" else mean[key] >= bound
        typer.echo(
            f"target mean {key} {'≤' if kind == 'max' else '≥'} {bound:g}: "
            f"{mean[key]:.3f} {'met' if ok else 'MISSED'}"
        )


@contextmanager
def _log_progress(log: Path) -> Iterator[Callable[[str, int, int], None]]:
    """A progress bar on stderr per seed's replay of ``log``, while the block runs."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total} scans"),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        transient=True,
    ) as bar:
        tasks: dict[str, int] = {}

        def progress(label: str, done: int, total: int) -> None:
            if label not in tasks:
                tasks[label] = bar.add_task(f"{log.name}, {label}", total=total)
            bar.update(tasks[label], completed=done)

        yield progress


@contextmanager
def _route_progress(seconds: float) -> Iterator[Callable[[float], None]]:
    """A progress bar on stderr over the drive, then a spinner for the replay, while the
    block runs."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    console = Console(stderr=True)
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.completed:.0f}/{task.total:.0f} sim s"),
        TimeRemainingColumn(),
        console=console,
        transient=True,
    ) as bar:
        task = bar.add_task("driving the route", total=seconds)

        def progress(t: float) -> None:
            bar.update(task, completed=t)
            if t >= seconds - 1.0:
                bar.update(task, description="replaying SLAM", completed=seconds)

        yield progress
