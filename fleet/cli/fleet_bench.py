"""`fleet bench fleet`, `follow`, `repetition` and `explore`: what fleets, and one robot on its
own, deliver on the floor, over worlds and seeds, where their repetition comes from, and what
an explored map is worth."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from fleet.cli.common import (
    _check_deconfliction,
    _fail,
    parse_seeds,
    print_result,
    progress_line,
    stamped_dir,
    world_file,
)
from fleet.cli.help_text import reflow
from fleet.cli.options import (
    BenchSpeedOpt,
    DeconflictionOpt,
    JsonOpt,
    RunRobotsOpt,
    RunTimeoutOpt,
    WorldOpt,
    WorldsOpt,
)

if TYPE_CHECKING:
    from fleet.params import FleetConfig
    from fleet.world import World

SeedsOpt = Annotated[str, typer.Option("--seeds", help="Seeds of the runs: 0,1,2 or 0-4 or a mix.")]


def _check_runs(
    robots: int, speed: float, timeout: float, deconfliction: str | None = None
) -> None:
    """Exit unless the runs' robots, speed, wall bound and deconfliction mode can be run."""
    if robots < 1:
        _fail("--robots must be >= 1")
    _check_deconfliction(deconfliction)
    if speed < 0 or not math.isfinite(speed):
        _fail(f"--speed must be a finite number >= 0, got {speed}")
    if timeout <= 0:
        _fail("--timeout must be > 0")


def _checked_config(path: Path) -> Path:
    """``path`` made absolute, once it loads as a fleet config; else the command ends with the
    loader's message, which names the file and the field."""
    from fleet.config import ConfigError
    from fleet.params import load_fleet_config

    try:
        load_fleet_config(path)
    except ConfigError as e:
        _fail(f"--config: {e}")
    return path.resolve()


def bench_fleet(
    worlds: WorldsOpt = "home",
    seeds: SeedsOpt = "0-4",
    robots: RunRobotsOpt = 3,
    speed: BenchSpeedOpt = 0.0,
    timeout: RunTimeoutOpt = 1200.0,
    run_root: Annotated[
        Path | None,
        typer.Option(
            "--run-root", help="Where each run's dir goes (default: runs/bench-fleet-<time>)."
        ),
    ] = None,
    as_json: JsonOpt = False,
    deconfliction: DeconflictionOpt = None,
    config: Annotated[
        Path | None,
        typer.Option(
            "--config",
            help="Parameter file every run uses (its `fleet up --config`), checked before the "
            "first run; default: the built-in configs/fleet.yaml.",
        ),
    ] = None,
) -> None:
    """Run `fleet up --headless --until-done` for every world and seed, and report what the
    fleet delivered on the floor, as the simulator measured it.

    Per run and as medians per world: coverage of the cleanable floor, repetition, makespan,
    the makespan the coordinator's first allocation priced (and the ratio), wall time,
    real-time factor, contacts (robot–wall and robot–robot), waypoints given up, and where the
    robots' time went (sweeping, transit, turning in place, giving way, escaping, idle). Each
    run's dir keeps its report.json, report.png and logs. Progress goes to stderr; the result
    is also written to RUN_ROOT/bench.json after every run.

    Examples: `fleet bench fleet --worlds home --seeds 0-4`;
    `fleet bench fleet --worlds small,home --seeds 0,1 --json`;
    `fleet bench fleet --worlds small --seeds 0-2 --config my-fleet.yaml` (an A/B of a parameter);
    `fleet bench fleet --worlds ../shared/data/maps/cob_ipa_apartment.yaml --seeds 0-2`.
    """
    from fleet.bench.fleet import Scenario, run_bench, table_lines

    _check_runs(robots, speed, timeout, deconfliction)
    options = ("--deconfliction", deconfliction) if deconfliction else ()
    if config is not None:
        options = (*options, "--config", str(_checked_config(config)))
    chosen = []
    for name in (w.strip() for w in worlds.split(",") if w.strip()):
        chosen.append(Scenario(Path(name).stem, world_file(name, "--worlds"), robots, options))
    if not chosen:
        _fail("--worlds: no world given")
    root = stamped_dir(run_root, "bench-fleet-%Y%m%d-%H%M%S")
    result = run_bench(root, chosen, parse_seeds(seeds), speed, timeout, progress_line)
    print_result(result, as_json, table_lines)


TurnOpt = Annotated[
    float,
    typer.Option(
        "--turn",
        help="Turn every world by this many degrees about its centre first, so that its walls "
        "run along no axis of the map, as in a home mapped from wherever a robot started "
        "(vector worlds only).",
    ),
]
RecordOpt = Annotated[
    Path | None,
    typer.Option(
        "--record",
        help="Write each run's scans and odometry into this directory as a CARMEN log, "
        "WORLD-seedS.log with its true poses beside it: `fleet slam replay` scores the SLAM on "
        "the coverage tour.",
    ),
]


def _follow_worlds(
    worlds: str, turn: float, config: Path | None
) -> tuple[FleetConfig, list[World]]:
    """The fleet config and the worlds of `fleet bench follow`, turned by ``turn`` degrees;
    a bad argument ends the command with its message."""
    from fleet.config import ConfigError, resolve_world
    from fleet.params import load_fleet_config
    from fleet.world import load_world, turned_world

    if not math.isfinite(turn):
        _fail(f"--turn must be a finite number of degrees, got {turn}")
    try:
        cfg = load_fleet_config(config)
        chosen = [
            load_world(resolve_world(w.strip()), cfg.robot.radius)
            for w in worlds.split(",")
            if w.strip()
        ]
        if turn:
            chosen = [turned_world(w, turn) for w in chosen]
    except ConfigError as e:
        _fail(str(e))
    if not chosen:
        _fail("--worlds: no world given")
    return cfg, chosen


def bench_follow(
    worlds: WorldsOpt = "small,home",
    seeds: SeedsOpt = "0-4",
    pose: Annotated[
        str,
        typer.Option(
            "--pose", help="What the robot drives on: slam (its own, as in fleet up) or truth."
        ),
    ] = "slam",
    latency: Annotated[
        float,
        typer.Option(
            "--latency",
            help="Sim seconds between a scan and its command taking effect (0: as fleet up "
            "--speed 0; up to sim.max_lag_s in real time).",
        ),
    ] = 0.0,
    config: Annotated[
        Path | None, typer.Option("--config", help="fleet.yaml to use instead of the default.")
    ] = None,
    turn: TurnOpt = 0.0,
    record: RecordOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """One robot drives the coordinator's whole coverage tour with the real path follower on
    the real simulator core, in one process and without the bus: what the plan and the follower
    lose on the floor, apart from peers, the market and the processes.

    Per run: coverage and repetition (the simulator's grid), sim time against the plan's
    estimate, contacts and waypoints given up (with where), the sweep's tracking error, the
    cross-track error on lanes (what the lanes' overlap, coordinator.lane_overlap, has to
    absorb), and the sim seconds per kind of control step (sweep, transit, turn in place,
    escape, ...); per world the medians and totals. Deterministic for a seed, and fast (the
    small world in seconds), so a change to the follower or the plan can be judged over many
    seeds and maps.

    Examples: `fleet bench follow`; `fleet bench follow --worlds home --seeds 0-9 --json`;
    `fleet bench follow --worlds ../shared/data/maps/cob_ipa_apartment.yaml --pose truth`;
    `fleet bench follow --worlds home --turn 20 --pose truth --record /tmp/tours`, then
    `fleet slam replay /tmp/tours/home-turned20-seed0.log`.
    """
    from fleet.bench.follow import follow_tour, run_line, summarize

    if pose not in ("slam", "truth"):
        _fail(f"--pose must be slam or truth, not {pose!r}")
    if latency < 0 or not math.isfinite(latency):
        _fail(f"--latency must be a finite number >= 0, got {latency}")
    cfg, chosen = _follow_worlds(worlds, turn, config)
    if record is not None:
        try:
            record.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            _fail(f"--record {record}: {e.strerror}")
    runs = []
    for world in chosen:
        for seed in parse_seeds(seeds):
            log = None if record is None else record / f"{world.name}-seed{seed}.log"
            runs.append(follow_tour(world, cfg, seed, pose, latency, record=log))
            print(run_line(runs[-1]), file=sys.stderr, flush=True)
    result = {"pose": pose, "latency_s": latency, "runs": runs, "worlds": summarize(runs)}
    if as_json:
        print(json.dumps(result))
        return
    for name, s in result["worlds"].items():
        typer.echo(
            f"{name}: {s['finished']}/{s['runs']} finished; medians: coverage "
            f"{100 * s['coverage']:.1f} %, repetition {100 * s['repetition']:.1f} %, time "
            f"×{s['time_over_estimate']} the plan's estimate; contacts {s['contacts']}, given "
            f"up {s['given_up']} in all; worst tracking p95 {100 * s['tracking_p95_m']:.1f} cm, "
            f"across lanes {100 * s['lane_cross_track_p95_m']:.1f} cm"
        )


def bench_repetition(
    run_dirs: Annotated[
        list[Path],
        typer.Argument(
            metavar="RUN_DIR...",
            help="Run dirs of `fleet up`, or dirs of them (`fleet bench fleet --run-root`).",
        ),
    ],
    subdivide: Annotated[
        int,
        typer.Option(
            "--subdivide",
            min=1,
            help="Count on the run's cleaning grid with every cell cut N x N (the simulator's "
            "5 cm cells hide or show lane overlap as lanes fall on them); 1: the simulator's.",
        ),
    ] = 1,
    as_json: JsonOpt = False,
) -> None:
    """Where each run's repetition comes from: every re-entry of a cell under the brush,
    charged to what the robot was doing and to the element of the coordinator's tour it drove.

    Replays each robot's true track (tracks.csv) with the simulator's brush over the run's
    cleaning grid (coverage.npz) and charges every entry of a cell after its first to the step
    kind in force (status.csv) and to the tour element driven (plans.jsonl, and the tour's
    elements in coordinator.sqlite): lanes (over another lane, over their own U-turn's floor,
    over floor a hop or transit swept, over their own line), turns inside lane groups, other
    passes (fill-in, strips), hops between passes by length, transits, detours, or turning in
    place, escapes, giving way, holding. The same for the tour alone (no follower, no peers)
    is the planned part. Figures are points of repetition; they sum to the replay's repetition,
    shown beside the simulator's. Needs the files `fleet up` writes since report format 2.

    Examples: `fleet bench repetition runs/20250101-120000`;
    `fleet bench repetition runs/bench-fleet-x --json`.
    """
    from fleet.bench.repetition import bench_repetition as run
    from fleet.bench.repetition import table_lines
    from fleet.report.summary import ReportError

    try:
        result = run(run_dirs, subdivide, progress_line)
    except ReportError as e:
        _fail(str(e))
    print_result(result, as_json, table_lines)


def bench_explore(
    world: WorldOpt = "home",
    seeds: SeedsOpt = "0-2",
    robots: Annotated[int, typer.Option("--robots", "-n", help="Robots exploring together.")] = 3,
    speed: BenchSpeedOpt = 0.0,
    timeout: RunTimeoutOpt = 1800.0,
    run_root: Annotated[
        Path | None,
        typer.Option(
            "--run-root", help="Where each run's dir goes (default: runs/bench-explore-<time>)."
        ),
    ] = None,
    as_json: JsonOpt = False,
) -> None:
    """Explore a world with N robots and with one alone, and clean on the map the N made.

    Per seed, four whole runs: `fleet explore` with N robots and with one (sim time to finish
    and path length, their ratio), the merged map scored against the true floor (free-space
    IoU, the share of true walls with a mapped wall within 5 cm), then `fleet up --map` on
    that map and `fleet up` on the world file, the same fleet and seed (true coverage of each,
    the gap in points, contacts). The targets (issue 27, home, 3 robots: time ≤ 0.5 × one
    robot's, IoU ≥ 0.95, walls ≥ 95 %, coverage within 1 point, 0 contacts) are judged on the
    worst seed. Each run's dir keeps its report and logs; the result is also written to
    RUN_ROOT/bench.json after every seed. Progress goes to stderr.

    Examples: `fleet bench explore --json`; `fleet bench explore --world small --seeds 0 -n 2`.
    """
    from fleet.bench.explore import run_bench, table_lines

    _check_runs(robots, speed, timeout)
    path = world_file(world, "--world")
    root = stamped_dir(run_root, "bench-explore-%Y%m%d-%H%M%S")
    result = run_bench(root, path, robots, parse_seeds(seeds), speed, timeout, progress_line)
    print_result(result, as_json, table_lines)


def register(
    app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app: typer.Typer
) -> None:
    bench_app.command("fleet", help=reflow(bench_fleet.__doc__ or ""))(bench_fleet)
    bench_app.command("follow", help=reflow(bench_follow.__doc__ or ""))(bench_follow)
    bench_app.command("repetition", help=reflow(bench_repetition.__doc__ or ""))(bench_repetition)
    bench_app.command("explore", help=reflow(bench_explore.__doc__ or ""))(bench_explore)
