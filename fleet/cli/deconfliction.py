"""``fleet bench deconfliction``: how long planning all transits of a round takes, and whole
fleets under each deconfliction mode (the runners in fleet.bench.deconfliction)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer

from fleet.cli.common import _fail, parse_seeds, stamped_dir
from fleet.cli.options import JsonOpt

# the family's table of runs needs this many columns of text
RUNS_TABLE_COLUMNS = 110

RoundsOpt = Annotated[
    int, typer.Option(min=1, help="Rounds per scenario (seeded: round i, seed i).")
]
JointTimeLimitOpt = Annotated[
    float, typer.Option(help="Seconds the joint fallback (CBS, or ECBS above 10 robots) may take.")
]
FleetSeedsOpt = Annotated[
    str,
    typer.Option(
        "--fleet-seeds",
        help="Also run whole fleets on the stress worlds (corridor with 3 robots, home with 6) "
        "under each mode, for these seeds (0-9, or 0,1,2); none by default, as each run takes "
        "a minute or two.",
    ),
]
ModesOpt = Annotated[str, typer.Option(help="Comma-separated modes the fleets run under.")]
FleetWorldsOpt = Annotated[
    str,
    typer.Option(
        help="Comma-separated stress worlds the fleets run on: corridor (3 robots), home (6)."
    ),
]
RunRootOpt = Annotated[
    Path | None,
    typer.Option(
        "--run-root", help="Where the fleets' run dirs go (default: runs/bench-deconf-<time>)."
    ),
]
FamilyOpt = Annotated[
    bool,
    typer.Option(
        "--family",
        help="Run only whole fleets on the generated family of stress worlds (two or three "
        "rooms, corridors 0.45-0.9 m wide and 1-4 m long, a doorway, an L), every member under "
        "every mode of --modes, and judge each mode against issue 30's targets (PASS/FAIL). "
        "No planning rounds are timed then.",
    ),
]
FamilySeedsOpt = Annotated[
    str, typer.Option("--family-seeds", help="Seeds of the family's fleets (0-2, or 0,1,2).")
]
FamilyMembersOpt = Annotated[
    str,
    typer.Option(
        "--family-members",
        help="Comma-separated members of the family to run (all by default): "
        "c0.45x2.5, c0.6x1, c0.6x4, c0.75x2.5, c0.9x2.5, door0.8, L0.6, 3rooms0.6.",
    ),
]


def register(app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app) -> None:
    bench_app.command("deconfliction")(bench_deconfliction)


def bench_deconfliction(
    rounds: RoundsOpt = 50,
    joint_time_limit: JointTimeLimitOpt = 1.0,
    as_json: JsonOpt = False,
    fleet_seeds: FleetSeedsOpt = "",
    modes: ModesOpt = "local,prioritized,cbs",
    fleet_worlds: FleetWorldsOpt = "corridor,home",
    run_root: RunRootOpt = None,
    family: FamilyOpt = False,
    family_seeds: FamilySeedsOpt = "0-2",
    family_members: FamilyMembersOpt = "all",
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
    from fleet.bench.deconfliction import time_rounds
    from fleet.params import load_fleet_config

    if family:
        _family(family_members, family_seeds, modes, run_root, as_json)
        return
    results: dict[str, Any] = time_rounds(load_fleet_config(), rounds, joint_time_limit)
    if fleet_seeds:
        results["fleets"] = _fleets(fleet_seeds, modes, fleet_worlds, run_root)
    if as_json:
        typer.echo(json.dumps(results))
        return
    _print_rounds(results)


def _print_rounds(results: dict[str, Any]) -> None:
    """The timed rounds, a column per scenario, and the fleets' figures (if run)."""
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
    from fleet.params import DECONFLICTION_MODES

    chosen = [m.strip() for m in modes.split(",") if m.strip()]
    bad = [m for m in chosen if m not in DECONFLICTION_MODES]
    if bad or not chosen:
        _fail(
            f"--modes: {', '.join(bad) or 'none given'}; choose from "
            f"{', '.join(DECONFLICTION_MODES)}"
        )
    return chosen


def _default_root(run_root: Path | None) -> Path:
    return stamped_dir(run_root, "bench-deconf-%Y%m%d-%H%M%S")


def _fleets(seeds: str, modes: str, worlds: str, run_root: Path | None) -> dict[str, dict]:
    """Whole fleets on the stress worlds under each mode (see the command's help)."""
    from fleet.bench.deconfliction import STRESS_WORLDS, run_stress_fleets

    chosen, seed_list = _modes(modes), parse_seeds(seeds)
    stress = dict(STRESS_WORLDS)
    names = [w.strip() for w in worlds.split(",") if w.strip()]
    unknown = [w for w in names if w not in stress]
    if unknown or not names:
        _fail(
            f"--fleet-worlds: {', '.join(unknown) or 'none given'}; choose from {', '.join(stress)}"
        )
    return run_stress_fleets(names, chosen, seed_list, _default_root(run_root))


def _family(names: str, seeds: str, modes: str, run_root: Path | None, as_json: bool) -> None:
    """Whole fleets on the generated family under each mode, and each mode's verdict (see the
    command's help)."""
    from fleet.bench.deconfliction import run_family
    from fleet.bench.world_family import members

    chosen, seed_list = _modes(modes), parse_seeds(seeds)
    try:
        family = members(names)
    except ValueError as e:
        _fail(f"--family-members: {e}")
    out = run_family(family, chosen, seed_list, _default_root(run_root))
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
