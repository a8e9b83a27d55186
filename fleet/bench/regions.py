"""The first allocation priced offline: runs of the tour against compact regions.

For each world and robot count: the coordinator's tasks of the world (its tour, cut as it cuts
it), the robots at the world's start poses, and travel priced as their bids price it
(:meth:`fleet.coordinator.planning.TaskPlanner.travel`). ``tour``: the tour's runs of about
equal time (``planners.auction.regions``) sold by sequential MiniMax auctions
(``planners.auction.allocate``), each run bid on as a whole, entered at either end, as the
market calls it. ``compact``: each robot's compact group (``TaskPlanner.compact_lots``), which
only it may win. Per mode: the makespan the allocation prices (the coordinator's estimate),
the robots' times, the travel in them (to the region, and between its tasks), and the time
the regions took to cut.
"""

from __future__ import annotations

import time
from typing import Any

from fleet.coordinator.planning import TaskPlanner
from fleet.params import FleetConfig
from fleet.world import World
from planners import auction

MODES = ("tour", "compact")


def compare(world: World, name: str, counts: list[int], cfg: FleetConfig) -> list[dict[str, Any]]:
    """One row per robot count and mode (the module docstring)."""
    planner = TaskPlanner(world, cfg)
    tasks = planner.tasks()
    travel = planner.travel()
    work = float(sum(t.time_s for t in tasks))
    rows = []
    for k in counts:
        poses = world.start_poses(k, cfg.robot.radius)
        starts = {f"robot-{i}": (float(p[0]), float(p[1])) for i, p in enumerate(poses)}
        for mode in MODES:
            t0 = time.perf_counter()
            if mode == "tour":
                lots = auction.regions(tasks, k)
            else:
                lots = planner.compact_lots(tasks, starts)
            cut_ms = 1e3 * (time.perf_counter() - t0)
            times = _times(lots, starts, travel)
            rows.append(
                {
                    "world": name,
                    "robots": k,
                    "mode": mode,
                    "tasks": len(tasks),
                    "makespan_s": round(max(times.values()), 1),
                    "times_s": {r: round(v, 1) for r, v in sorted(times.items())},
                    "travel_s": round(sum(times.values()) - work, 1),
                    "cut_ms": round(cut_ms, 1),
                }
            )
    return rows


def _times(
    lots: tuple[auction.Lot, ...], starts: dict[str, tuple[float, float]], travel: auction.Travel
) -> dict[str, float]:
    """Each robot's committed time after the lots are sold: sequential MiniMax auctions over
    all lots, each lot bid on as one task from its entry to its exit, a lot for one robot
    only bid on by that robot."""
    held = {r: auction.Commitment(xy) for r, xy in starts.items()}
    left = list(lots)
    while left:
        bids = [
            (auction.make_bid(r, lot.id, lot.entry, lot.exit, lot.time_s, held[r], travel), lot)
            for lot in left
            for r in held
            if lot.robot in (None, r)
        ]
        best = auction.winner([b for b, _ in bids])
        if best is None:
            break
        lot = next(lot for b, lot in bids if b is best)
        held[best.robot] = held[best.robot].won(best, lot.entry, lot.exit, lot.time_s)
        left.remove(lot)
    return {r: c.total_s for r, c in held.items()}


def table_lines(rows: list[dict[str, Any]]) -> list[str]:
    out = [
        "world  robots  mode     tasks  makespan s  travel s  cut ms  robots' times s",
    ]
    for r in rows:
        times = " ".join(f"{v:.0f}" for v in r["times_s"].values())
        out.append(
            f"{r['world']:<6} {r['robots']:>6}  {r['mode']:<7} {r['tasks']:>5}  "
            f"{r['makespan_s']:>10.1f}  {r['travel_s']:>8.1f}  {r['cut_ms']:>6.0f}  {times}"
        )
    return out
