"""`fleet bench scale`: what a fleet costs as it grows, robots 3, 6, 12, 20 on one floor.

Each point is ``fleet up --headless --until-done --speed 0`` with N robots
(:class:`fleet.supervisor.runner.RunningFleet`). Its cost is measured over a window of
``window_s`` sim seconds that starts at the job's first award, so the coordinator's first
planning (which runs the sim clock too) is not in it. At the window's two ends the bench
looks (:func:`look`) at every process of the run's table and at ``fleet up`` itself: CPU time
(``utime + stime`` of ``/proc/PID/stat``) and resident memory (``VmRSS``). From the two looks:

- the real-time factor: sim seconds over wall seconds in the window;
- per process its share of a core (CPU seconds over wall seconds), and per agent its CPU per
  scan: CPU seconds over the scans the window held at ``lidar.rate_hz`` (at ``--speed 0`` the
  simulator waits for the agents, so every agent handles every scan);
- per process its RSS at the window's end.

From the coordinator's events over the whole run: each auction's time (``auction``: "N lots in
T ms", a lot at a time) and each round of planned transits (``transits``: "... in T ms").
With ``to_end`` the run goes on to its end and its report.json gives coverage, repetition,
makespan and contacts; without it the run is stopped (SIGTERM) at the window's end.
"""

from __future__ import annotations

import json
import os
import re
import signal
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fleet.bench.soak import pids_of, rss_kb
from fleet.supervisor.runner import RunningFleet

RESULT_FILE = "bench.json"
# the first award is waited for this long (wall s) at least, and on while the sim clock moves:
# 20 agents starting on two cores and the first plan of a large floor take minutes
START_WAIT_S = 900.0
# a window's end is waited for this long (wall s) at least, and on while the sim clock moves
WINDOW_WAIT_S = 600.0
# a run to its end, and fleet up's report after SIGTERM, are waited for this long (wall s)
END_WAIT_S = 3600.0
LOOK_EVERY_S = 1.0
AUCTION = re.compile(r"(\d+) lots in (\d+) ms")
TRANSITS = re.compile(r"(\d+) robots by \S+ in (\d+) ms")
CLOCK_TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")


@dataclass(frozen=True)
class Look:
    """The run at one moment: sim and wall time, and per process (by name) its CPU seconds
    and RSS in kB (None when it was gone)."""

    sim_s: float
    wall_s: float
    cpu_s: dict[str, float | None]
    rss_kb: dict[str, int | None]


def cpu_seconds(pid: int) -> float | None:
    """User plus system CPU seconds of process ``pid`` so far; None when it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    # the fields after the command name (which may hold spaces and parentheses): state is
    # the first, utime and stime the 12th and 13th (proc(5): fields 14 and 15)
    fields = text[text.rindex(")") + 2 :].split()
    return (int(fields[11]) + int(fields[12])) * CLOCK_TICK_S


def look(run_dir: Path, sim_s: float, wall_s: float) -> Look:
    """Every process of the run in ``run_dir`` (``fleet up`` as ``up``) at ``sim_s``."""
    pids = pids_of(run_dir)
    return Look(
        sim_s,
        wall_s,
        {n: cpu_seconds(p) for n, p in pids.items()},
        {n: rss_kb(p) for n, p in pids.items()},
    )


def _summary(values: Sequence[float]) -> dict[str, float | int | None]:
    if not values:
        return {"n": 0, "median": None, "max": None}
    return {
        "n": len(values),
        "median": round(statistics.median(values), 2),
        "max": round(max(values), 2),
    }


def window_figures(a: Look, b: Look, scan_hz: float) -> dict[str, Any]:
    """The cost of the run between looks ``a`` and ``b`` (see the module): real-time factor,
    per process its core share and RSS, per agent its CPU ms per scan, and their summaries."""
    sim, wall = b.sim_s - a.sim_s, b.wall_s - a.wall_s
    procs: dict[str, dict[str, Any]] = {}
    for name in b.cpu_s:
        before, after = a.cpu_s.get(name), b.cpu_s[name]
        rss = b.rss_kb.get(name)
        row: dict[str, Any] = {"rss_mb": round(rss / 1024, 1) if rss is not None else None}
        if before is not None and after is not None and wall > 0:
            cpu = after - before
            row["core_share"] = round(cpu / wall, 3)
            if name.startswith("robot-") and sim > 0:
                row["cpu_ms_per_scan"] = round(1e3 * cpu / (sim * scan_hz), 2)
        procs[name] = row
    agents = [p for n, p in procs.items() if n.startswith("robot-")]
    per_scan = [p["cpu_ms_per_scan"] for p in agents if "cpu_ms_per_scan" in p]
    shares = [p["core_share"] for p in procs.values() if "core_share" in p]
    return {
        "window_sim_s": round(sim, 1),
        "window_wall_s": round(wall, 1),
        "real_time_factor": round(sim / wall, 2) if wall > 0 else None,
        "agent_cpu_ms_per_scan": _summary(per_scan),
        "agent_rss_mb": _summary([p["rss_mb"] for p in agents if p["rss_mb"] is not None]),
        "cores_busy": round(sum(shares), 2),
        "processes": procs,
    }


def coordinator_times(events: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Each auction's time per lot and each transit round's time (ms), from the
    coordinator's ``auction`` and ``transits`` events."""
    per_lot, rounds = [], []
    for e in events:
        if e["kind"] == "auction" and (m := AUCTION.search(e["detail"])) and int(m[1]):
            per_lot.append(int(m[2]) / int(m[1]))
        elif e["kind"] == "transits" and (m := TRANSITS.search(e["detail"])):
            rounds.append(float(m[2]))
    return {"auction_ms_per_lot": _summary(per_lot), "transit_round_ms": _summary(rounds)}


def _end_figures(report: dict[str, Any] | None) -> dict[str, Any]:
    if report is None:
        return {"status": "no report"}
    keys = ("status", "coverage", "repetition", "makespan_s", "plan_estimate_s", "collisions")
    return {k: report.get(k) for k in keys}


def _watch_window(
    fleet: RunningFleet, t0: float, window_s: float, progress: Callable[[str], None]
) -> tuple[Look, Look] | str:
    """The looks at the window's start (the first award) and at its end, or at the last
    moment every process was there; or why the window could not be had."""
    if not fleet.wait(lambda: fleet.first_award() is not None, START_WAIT_S, poll=LOOK_EVERY_S):
        return f"no award by {fleet.sim_t():.1f} s sim (fleet up exit {fleet.proc.poll()})"
    start = look(fleet.dir, fleet.sim_t(), time.monotonic() - t0)
    last = start
    guard = fleet.guard(WINDOW_WAIT_S, sim_s=window_s * 10)
    while last.sim_s < start.sim_s + window_s and not guard.expired():
        time.sleep(LOOK_EVERY_S)
        now = look(fleet.dir, fleet.sim_t(), time.monotonic() - t0)
        if fleet.proc.poll() is not None or None in now.cpu_s.values():
            break
        last = now
    progress(
        f"  window {last.sim_s - start.sim_s:.1f} s sim in {last.wall_s - start.wall_s:.1f} s wall"
    )
    return start, last


@dataclass(frozen=True)
class Settings:
    """What every point of a bench shares: the simulator's seed, the window (sim s), whether
    each run goes on to its end, the scan rate (Hz) and more options of ``fleet up``."""

    seed: int
    window_s: float
    to_end: bool
    scan_hz: float
    options: tuple[str, ...] = ()


def run_point(
    run_dir: Path, world: str, robots: int, settings: Settings, progress: Callable[[str], None]
) -> dict[str, Any]:
    """One fleet of ``robots`` on ``world``: its window's cost, its coordinator's times and,
    with ``settings.to_end``, what it delivered."""
    t0 = time.monotonic()
    point: dict[str, Any] = {"robots": robots, "run_dir": str(run_dir)}
    fleet = RunningFleet(run_dir, world, robots, settings.seed, options=settings.options)
    try:
        looks = _watch_window(fleet, t0, settings.window_s, progress)
        if not settings.to_end and fleet.proc.poll() is None:
            fleet.proc.send_signal(signal.SIGTERM)
        report = fleet.finish(END_WAIT_S)
        events = fleet.events()
    finally:
        fleet.cleanup()
    if isinstance(looks, str):
        point["stopped"] = looks
    else:
        point |= window_figures(*looks, settings.scan_hz)
    point |= coordinator_times(events)
    point["wall_s"] = round(time.monotonic() - t0, 1)
    if settings.to_end:
        point |= _end_figures(report)
    point["left_processes"] = fleet.left
    return point


def run_bench(
    root: Path,
    worlds: Sequence[tuple[str, str]],
    robots: Sequence[int],
    settings: Settings,
    progress: Callable[[str], None],
) -> dict[str, Any]:
    """Every world (name, file) with every robot count; written to ``root/bench.json`` after
    each point."""
    root.mkdir(parents=True, exist_ok=True)
    result: dict[str, Any] = {
        "seed": settings.seed,
        "window_s": settings.window_s,
        "to_end": settings.to_end,
        "scan_hz": settings.scan_hz,
        "points": [],
    }
    for name, path in worlds:
        for n in robots:
            progress(f"{name}, {n} robots")
            point = {"world": name} | run_point(root / f"{name}-{n}", path, n, settings, progress)
            result["points"].append(point)
            (root / RESULT_FILE).write_text(json.dumps(result, indent=1))
            progress("  " + _row(point))
    return result


def _fmt(value: Any, spec: str = "") -> str:
    return "-" if value is None else format(value, spec)


def _row(p: dict[str, Any]) -> str:
    if "stopped" in p:
        return f"{p['world']:<10} {p['robots']:>3}  stopped: {p['stopped']}"
    ms, rss = p["agent_cpu_ms_per_scan"], p["agent_rss_mb"]
    coord = p["processes"].get("coordinator", {})
    lot, rnd = p["auction_ms_per_lot"], p["transit_round_ms"]
    line = (
        f"{p['world']:<10} {p['robots']:>3}  {_fmt(p['real_time_factor'], '5.2f')}  "
        f"{_fmt(ms['median'], '6.2f')} {_fmt(ms['max'], '6.2f')}  "
        f"{_fmt(p['cores_busy'], '4.2f')}  {_fmt(coord.get('core_share'), '5.3f')}  "
        f"{_fmt(lot['median'], '5.1f')} {_fmt(lot['max'], '6.1f')}  "
        f"{_fmt(rnd['median'], '5.0f')} ({rnd['n']})  "
        f"{_fmt(rss['median'], '5.0f')} {_fmt(coord.get('rss_mb'), '5.0f')}"
    )
    if "status" in p:
        c = p.get("collisions") or {}
        line += (
            f"  {p['status']}: coverage {_fmt(p.get('coverage'), '.1%')}, makespan "
            f"{_fmt(p.get('makespan_s'), '.1f')} s, contacts wall {c.get('robot_wall', '-')} "
            f"robot {c.get('robot_robot', '-')}"
        )
    return line


def table_lines(result: dict[str, Any]) -> list[str]:
    """The points as a table: one row per world and robot count."""
    return [
        f"seed {result['seed']}, window {result['window_s']:.0f} s sim from the first award"
        + ("; each run to its end" if result["to_end"] else ""),
        "world    robots   RTF  agent ms/scan   cores  coord  ms/lot med max  "
        "round ms (n)  RSS MB agent coord",
        *(_row(p) for p in result["points"]),
    ]
