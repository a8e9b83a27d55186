"""`fleet bench fleet`: whole `fleet up` runs over worlds and seeds, and what they delivered.

Each run is ``fleet up --headless --until-done --speed S`` in its own run dir (the report is the
one a user gets). Per run: coverage, repetition, makespan, the makespan the coordinator's first
allocation priced (``plan_estimate_s``) and their ratio, wall time, real-time factor (sim
seconds per wall second), contacts, waypoints given up, and where the robots' time went (sim
seconds summed over robots per kind of control step, ``fleet.protocol.TIME_KINDS``), the
coordinator's ``unreachable`` events (a transit or task it could not route), its ``stuck``
events (a robot at work that got nowhere for ``coordinator.stall_s``; those with a peer near,
two robots that held each other, counted apart), and where the
missed floor lies (report.json's ``missed``: by clearance from walls and furniture). Per
world: the medians, and the worst run's contacts and given-up waypoints.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fleet.coordinator.market import PEER_HELD
from fleet.protocol import TIME_KINDS
from fleet.report.summary import MISSED_BANDS
from fleet.supervisor.runner import RunningFleet

MEDIAN_KEYS = (
    "coverage",
    "repetition",
    "makespan_s",
    "plan_estimate_s",
    "makespan_over_estimate",
    "wall_s",
    "real_time_factor",
)


def run_figures(report: dict[str, Any] | None, world: str, seed: int) -> dict[str, Any]:
    """The figures of one run from its report.json (``status`` "no report" without one)."""
    if report is None:
        return {"world": world, "seed": seed, "status": "no report"}
    robots = report.get("robots") or {}
    skipped = [r.get("skipped_waypoints") for r in robots.values()]
    time_use = {k: 0.0 for k in TIME_KINDS}
    for r in robots.values():
        for k, t in (r.get("time_s") or {}).items():
            time_use[k] = round(time_use.get(k, 0.0) + t, 1)
    makespan, estimate = report.get("makespan_s"), report.get("plan_estimate_s")
    wall = report.get("wall_s") or 0.0
    events = report.get("events") or []
    return {
        "world": world,
        "seed": seed,
        "status": report["status"],
        "coverage": report["coverage"],
        "repetition": report["repetition"],
        "makespan_s": makespan,
        "plan_estimate_s": estimate,
        "makespan_over_estimate": round(makespan / estimate, 3) if makespan and estimate else None,
        "wall_s": wall,
        "real_time_factor": round(report["sim_time_s"] / wall, 2) if wall > 0 else None,
        "contacts": report["collisions"],
        "skipped_waypoints": sum(s for s in skipped if s is not None),
        "unreachable": [
            f"{e['robot']} {e['task']}: {e['detail']}" for e in events if e["kind"] == "unreachable"
        ],
        "stuck": sum(e["kind"] == "stuck" for e in events),
        "stuck_by_peer": sum(e["kind"] == "stuck" and PEER_HELD in e["detail"] for e in events),
        "time_s": time_use,
        "missed": report.get("missed"),
    }


def _median(values: list[Any]) -> float | None:
    known = [v for v in values if v is not None]
    return round(float(np.median(known)), 4) if known else None


def world_summary(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Medians over the runs that produced a report; contacts and given-up waypoints as the
    worst run's and the total; the finished count."""
    done = [r for r in runs if r["status"] != "no report"]
    out: dict[str, Any] = {"runs": len(runs), "finished": sum(r["status"] == "done" for r in runs)}
    for key in MEDIAN_KEYS:
        out[key] = _median([r[key] for r in done])
    contacts = [r["contacts"]["robot_wall"] + r["contacts"]["robot_robot"] for r in done]
    out["contacts_total"] = sum(contacts)
    out["contacts_worst_run"] = max(contacts, default=None)
    out["skipped_total"] = sum(r["skipped_waypoints"] for r in done)
    out["stuck_total"] = sum(r.get("stuck", 0) for r in done)
    out["stuck_by_peer_total"] = sum(r.get("stuck_by_peer", 0) for r in done)
    out["time_s_median"] = {k: _median([r["time_s"][k] for r in done]) for k in TIME_KINDS}
    out["missed_median"] = {
        band: _median([(r.get("missed") or {}).get(band) for r in done]) for band in MISSED_BANDS
    }
    return out


@dataclass(frozen=True)
class Scenario:
    """Runs of one kind: ``fleet up`` on ``world`` (a path) with ``robots`` and ``options``,
    reported under ``name``."""

    name: str
    world: str
    robots: int
    options: tuple[str, ...] = ()


def run_bench(
    root: Path,
    scenarios: Sequence[Scenario],
    seeds: Sequence[int],
    speed: float,
    timeout_s: float,
    progress: Callable[[str], None],
) -> dict[str, Any]:
    """``fleet up`` for every (scenario, seed). The result is also written to
    ``root / bench.json`` after every run, so an interrupted bench keeps what it measured."""
    root.mkdir(parents=True, exist_ok=True)
    result: dict[str, Any] = {
        "robots": {s.name: s.robots for s in scenarios},
        "speed": speed,
        "seeds": list(seeds),
        "root": str(root),
        "runs": [],
        "worlds": {},
    }
    total = len(scenarios) * len(seeds)
    for sc in scenarios:
        mine = []
        for seed in seeds:
            progress(f"[{len(result['runs']) + 1}/{total}] {sc.name} seed {seed} …")
            run_dir = root / f"{sc.name.replace('/', '-')}-seed{seed}"
            fleet = RunningFleet(
                run_dir,
                sc.world,
                sc.robots,
                seed,
                timeout_s=timeout_s,
                speed=speed,
                options=sc.options,
            )
            try:
                report = fleet.finish(timeout=timeout_s + 120.0)
            finally:
                fleet.cleanup()
            figures = run_figures(report, sc.name, seed)
            figures["run_dir"] = str(run_dir)
            mine.append(figures)
            result["runs"].append(figures)
            progress("    " + run_line(figures))
            result["worlds"][sc.name] = world_summary(mine)
            (root / "bench.json").write_text(json.dumps(result, indent=2) + "\n")
    return result


def _pct(v: float | None) -> str:
    return f"{100 * v:.1f} %" if v is not None else "–"


def run_line(r: dict[str, Any]) -> str:
    if r["status"] == "no report":
        return f"{r['world']} seed {r['seed']}: no report (see {r.get('run_dir', '')})"
    c = r["contacts"]
    return (
        f"{r['status']}: coverage {_pct(r['coverage'])}, repetition {_pct(r['repetition'])}, "
        f"makespan {r['makespan_s']} s (plan {r['plan_estimate_s']} s, "
        f"×{r['makespan_over_estimate']}), {r['wall_s']} s wall, RTF {r['real_time_factor']}, "
        f"contacts wall {c['robot_wall']} robot {c['robot_robot']}, "
        f"given up {r['skipped_waypoints']}, stuck {r.get('stuck', 0)} "
        f"({r.get('stuck_by_peer', 0)} by a peer)"
        + (
            "; missed " + ", ".join(f"{b} {_pct(v)}" for b, v in r["missed"].items())
            if r.get("missed")
            else ""
        )
    )


def table_lines(result: dict[str, Any]) -> list[str]:
    lines = []
    for name, s in result["worlds"].items():
        t = s["time_s_median"]
        lines += [
            f"{name}: {s['finished']}/{s['runs']} finished; medians: coverage "
            f"{_pct(s['coverage'])}, repetition {_pct(s['repetition'])}, makespan "
            f"{s['makespan_s']} s, plan estimate {s['plan_estimate_s']} s "
            f"(×{s['makespan_over_estimate']}), wall {s['wall_s']} s, RTF "
            f"{s['real_time_factor']}",
            f"  contacts {s['contacts_total']} in all (worst run {s['contacts_worst_run']}), "
            f"waypoints given up {s['skipped_total']} in all, stuck {s['stuck_total']} in all "
            f"({s['stuck_by_peer_total']} by a peer)",
            "  robot-seconds (median over runs, summed over robots): "
            + ", ".join(f"{k} {t[k]}" for k in TIME_KINDS),
            "  floor missed by clearance from walls and furniture (median, of the cleanable): "
            + ", ".join(f"{band} {_pct(v)}" for band, v in s["missed_median"].items()),
        ]
    return lines
