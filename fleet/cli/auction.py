"""`fleet bench auction`: what an auction lot costs with many robots and many tasks, over a real
router (the runner in fleet.bench.auction)."""

from __future__ import annotations

from typing import Annotated

import typer

from fleet.cli.common import _fail, print_result, progress_line, world_file
from fleet.cli.help_text import reflow
from fleet.cli.options import JsonOpt, WorldOpt


def bench_auction(
    world: WorldOpt = "home",
    robots: Annotated[
        int, typer.Option("--robots", "-n", min=1, help="Bidder processes, one per robot.")
    ] = 20,
    tasks: Annotated[
        int,
        typer.Option(
            "--tasks",
            min=1,
            help="About how many tasks the floor's tour is cut into (cut at points 0.25 m "
            "apart at most, so a small floor may give fewer).",
        ),
    ] = 500,
    seed: Annotated[int, typer.Option("--seed", help="Seed of where the robots stand.")] = 0,
    as_json: JsonOpt = False,
) -> None:
    """Sell every task of a floor's tour, one lot a round, to ROBOTS bidder processes over a
    Zenoh router on a free loopback port, and time each lot.

    Each bidder is a robot's market as an agent runs it (its own Zenoh session, the floor plan
    for travel, its won queue from its awards, one answer a round); the coordinator's side is
    the real auctioneer, which sends the winner its queue and waits for its acknowledgement
    before the next round. Reports per lot the wall time from the call to the acknowledgement
    (median, p95, max) and of the bids alone, the coordinator's CPU per lot, a robot's CPU per
    answer, and the baseline: the same auctions in one process with no bus, their time per
    lot and makespan, and whether both allocate alike.

    Example: fleet bench auction --robots 20 --tasks 500 (about a minute on two cores).
    """
    from fleet.bench.auction import run_bench, table_lines

    path = world_file(world)
    step = max(tasks // 10, 1)

    def progress(done: int, total: int) -> None:
        if done % step == 0 or done == total:
            progress_line(f"sold {done}/{total} lots")

    try:
        result = run_bench(path, robots, tasks, seed, progress)
    except (RuntimeError, ValueError) as e:
        _fail(str(e))
    print_result(result, as_json, table_lines)


def register(
    app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app: typer.Typer
) -> None:
    bench_app.command("auction", help=reflow(bench_auction.__doc__ or ""))(bench_auction)
