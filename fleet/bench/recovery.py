"""`fleet bench recovery`: how fast the fleet notices a lost robot and auctions its work again,
and what failures cost the job — measured on real fleets (`fleet up`, real signals).

Latency trials: in runs of ``fleet up``, a robot at a time is SIGKILLed (then respawned) or
SIGSTOPped (then continued), alternately. Detection is the Unix time of the coordinator's
``lost`` event minus the time the signal was sent; reassignment, the time from ``lost`` to the
last ``reassigned`` event of the work it had, or of the parts that replaced it where its body
lies in the way (none when it held none).

Scenarios, each a whole run on the same world and seed: no failure; robot-1 SIGKILLed at a
third of the no-failure makespan (sim time); the same, then respawned; the coordinator
SIGKILLed at a third and restarted.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import re
import signal
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from fleet.supervisor.runner import RunningFleet, read_events

SETTLE_S = 1.0
DETECT_TIMEOUT_S = 10.0
REJOIN_TIMEOUT_S = 60.0


def to_reassign(events: list[dict], reopened: set[str]) -> set[str]:
    """The tasks that must be ``reassigned`` for ``reopened`` to count as re-sold: each one,
    or, where it was ``rerouted`` round a body, the open parts that replaced it (named in the
    event: "round the body: 2 part(s) t01.2 t01.3, 0.10 m² blocked")."""
    due = set(reopened)
    for e in events:
        if e["kind"] == "rerouted" and e["task"] in due:
            named = re.search(r"part\(s\)([^,]*)", e["detail"])
            due.discard(e["task"])
            due.update(named.group(1).split() if named else ())
    return due


def events_after(events: list[dict], seq: int, kind: str, robot: str | None = None) -> list[dict]:
    """The ``kind`` events after sequence number ``seq`` (of ``robot``, when given)."""
    return [
        e
        for e in events
        if e["seq"] > seq and e["kind"] == kind and (robot is None or e["robot"] == robot)
    ]


def _trial(fleet: RunningFleet, victim: str, hang: bool) -> dict[str, Any] | None:
    """One loss and recovery of ``victim``; None when the run ended first."""
    before = max((e["seq"] for e in fleet.events()), default=0)
    sent = fleet.signal(victim, signal.SIGSTOP if hang else signal.SIGKILL)

    def lost() -> list[dict]:
        return events_after(fleet.events(), before, "lost", victim)

    if not fleet.wait(lost, DETECT_TIMEOUT_S):
        return None
    event = lost()[0]
    reopened = {e["task"] for e in events_after(fleet.events(), event["seq"], "reopened", victim)}

    def due() -> set[str]:
        return to_reassign(events_after(fleet.events(), event["seq"], "rerouted"), reopened)

    def reassigned() -> list[dict]:
        sold = events_after(fleet.events(), event["seq"], "reassigned")
        return [e for e in sold if e["task"] in due()]

    fleet.wait(lambda: {e["task"] for e in reassigned()} >= due(), DETECT_TIMEOUT_S)
    done = reassigned()
    if hang:
        fleet.signal(victim, signal.SIGCONT)
    else:
        fleet.verb("respawn", victim)
    rejoined = fleet.wait(
        lambda: events_after(fleet.events(), event["seq"], "rejoined", victim), REJOIN_TIMEOUT_S
    )
    return {
        "signal": "STOP" if hang else "KILL",
        "robot": victim,
        "detection_s": round(event["wall"] - sent, 4),
        "tasks_reopened": len(reopened),
        "reassignment_s": round(max(e["wall"] for e in done) - event["wall"], 4) if done else None,
        "all_reassigned": {e["task"] for e in done} >= due(),
        "rejoined": rejoined,
    }


def latency_trials(
    root: Path, world: str, robots: int, seed: int, kills: int, progress: Callable[[str], None]
) -> list[dict[str, Any]]:
    """``kills`` SIGKILL trials and as many SIGSTOP ones, over as many runs as it takes."""
    trials: list[dict[str, Any]] = []
    victims = itertools.cycle([f"robot-{i}" for i in range(robots)])
    for run in itertools.count():
        if sum(t["signal"] == "KILL" for t in trials) >= kills:
            break
        fleet = RunningFleet(root / f"latency-{run}", world, robots, seed)
        try:
            fleet.wait(lambda fleet=fleet: fleet.events("auction"), 120.0)
            while fleet.proc.poll() is None and len(trials) < 2 * kills:
                time.sleep(SETTLE_S)
                hang = len(trials) % 2 == 1
                result = _trial(fleet, next(victims), hang)
                if result is None:
                    break
                trials.append(result)
                progress(
                    f"trial {len(trials)}/{2 * kills}: SIG{result['signal']} {result['robot']}: "
                    f"detected in {result['detection_s']:.3f} s"
                )
        finally:
            fleet.cleanup()
    return trials


def quantiles(values: list[float]) -> dict[str, float | None]:
    if not values:
        return {"n": 0, "median": None, "p95": None, "max": None}
    a = np.asarray(values)
    return {
        "n": len(values),
        "median": round(float(np.median(a)), 4),
        "p95": round(float(np.percentile(a, 95)), 4),
        "max": round(float(a.max()), 4),
    }


def summarize(trials: list[dict[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for sig in ("KILL", "STOP"):
        mine = [t for t in trials if t["signal"] == sig]
        out[f"detection_{sig.lower()}_s"] = quantiles([t["detection_s"] for t in mine])
    out["reassignment_s"] = quantiles(
        [t["reassignment_s"] for t in trials if t["reassignment_s"] is not None]
    )
    out["rejoined"] = sum(t["rejoined"] for t in trials)
    out["trials"] = len(trials)
    return out


def _scenario(
    root: Path, name: str, world: str, robots: int, seed: int, at_s: float | None
) -> dict[str, Any]:
    """One whole run; with ``at_s`` the scenario's failure is made at that sim time."""
    fleet = RunningFleet(root / name, world, robots, seed)
    failure: dict[str, Any] = {}
    try:
        if at_s is not None:
            clock = fleet.clock()
            fleet.wait(lambda: clock.t >= at_s, 900.0, poll=0.02)
            victim = "coordinator" if name == "coordinator-restart" else "robot-1"
            before = max((e["seq"] for e in fleet.events()), default=0)
            failure = {"victim": victim, "sim_s": round(clock.t, 2)}
            fleet.signal(victim, signal.SIGKILL)
            if name == "kill-respawn":
                fleet.wait(lambda: events_after(fleet.events(), before, "lost", victim), 10.0)
                fleet.verb("respawn", victim)
            elif name == "coordinator-restart":
                time.sleep(2.0)
                fleet.verb("respawn", victim)
        report = fleet.finish() or {}
    finally:
        fleet.cleanup()
    events = fleet.events()
    result = {
        "scenario": name,
        "status": report.get("status"),
        "coverage": report.get("coverage"),
        "repetition": report.get("repetition"),
        "makespan_s": report.get("makespan_s"),
        "wall_s": report.get("wall_s"),
        "collisions": report.get("collisions"),
        "overlaps": report.get("overlaps"),
        **failure,
    }
    if name == "kill-respawn":
        rejoin = next((e for e in events if e["kind"] == "rejoined"), None)
        result["respawned_robot_tasks_done"] = (
            len(events_after(events, rejoin["seq"], "done", "robot-1")) if rejoin else 0
        )
    return result


def auction_ms_per_lot(root: Path) -> dict[str, float | None]:
    """From every run's ``auction`` events: wall milliseconds per lot sold."""
    per_lot = []
    for state in root.glob("*/coordinator.sqlite"):
        for e in read_events(state):
            if e["kind"] == "auction":
                lots, _, rest = e["detail"].partition(" lots in ")
                with contextlib.suppress(ValueError):
                    per_lot.append(float(rest.split()[0]) / int(lots))
    return quantiles(per_lot)


def run_bench(
    root: Path,
    world: str,
    robots: int,
    seed: int,
    kills: int,
    scenarios: bool,
    progress: Callable[[str], None],
    sweep_moments: int = 0,
    respawn_after_s: float | None = None,
) -> dict[str, Any]:
    """Latency trials, the four scenarios and, with ``sweep_moments``, robot-1 killed at that
    many moments of the no-failure run (:mod:`fleet.bench.kill_sweep`)."""
    from fleet.bench.kill_sweep import sweep

    root.mkdir(parents=True, exist_ok=True)
    result: dict[str, Any] = {"world": world, "robots": robots, "seed": seed, "root": str(root)}
    if kills > 0:
        trials = latency_trials(root, world, robots, seed, kills, progress)
        result["latency"] = summarize(trials)
        result["trials"] = trials
    base = None
    if scenarios or sweep_moments:
        progress("scenario: no failure")
        base = _scenario(root, "no-failure", world, robots, seed, None)
    if scenarios and base is not None:
        runs = [base]
        makespan = base["makespan_s"]
        if makespan:
            for name in ("kill", "kill-respawn", "coordinator-restart"):
                progress(f"scenario: {name} at {makespan / 3:.0f} s sim")
                runs.append(_scenario(root, name, world, robots, seed, makespan / 3))
            for r in runs[1:]:
                if r["makespan_s"]:
                    r["makespan_ratio"] = round(r["makespan_s"] / makespan, 3)
        result["scenarios"] = runs
    if sweep_moments and base is not None and base["makespan_s"]:
        result["no_failure"] = base
        result["sweep"] = sweep(
            root, world, robots, seed, sweep_moments, respawn_after_s, base, progress
        )
    result["auction_ms_per_lot"] = auction_ms_per_lot(root)
    (root / "bench.json").write_text(json.dumps(result, indent=2) + "\n")
    return result


def table_lines(result: dict[str, Any]) -> list[str]:
    lines = []
    lat = result.get("latency")
    if lat:
        for key in ("detection_kill_s", "detection_stop_s", "reassignment_s"):
            q = lat[key]
            lines.append(
                f"{key:<18} n={q['n']:<3} median {q['median']} s  p95 {q['p95']} s  "
                f"max {q['max']} s"
            )
        lines.append(f"rejoined after {lat['rejoined']} of {lat['trials']} trials")
    for r in result.get("scenarios", []):
        lines.append(
            f"{r['scenario']:<20} {r['status']}: coverage {r['coverage']}, makespan "
            f"{r['makespan_s']} s (×{r.get('makespan_ratio', 1.0)}), collisions "
            f"{r['collisions']}, overlaps {r['overlaps']}"
            + (
                f", respawned robot finished {r['respawned_robot_tasks_done']} tasks"
                if "respawned_robot_tasks_done" in r
                else ""
            )
        )
    if "sweep" in result:
        from fleet.bench.kill_sweep import sweep_lines

        lines += sweep_lines(result["sweep"])
    q = result["auction_ms_per_lot"]
    lines.append(f"auction: median {q['median']} ms per lot sold, p95 {q['p95']} (n={q['n']})")
    return lines
