"""The generated family's fleets against issue 30's targets, per deconfliction mode.

A run's figures are those of :func:`fleet.bench.fleet.run_figures` with the family member and
the mode split out of the scenario's name (``<member>/<mode>``). Per mode, over every member
and seed, each target passes or fails:

- ``no unreachable``: no ``unreachable`` event from the coordinator (every goal of a family
  member is reachable on the grid: its rooms are connected for a robot centre);
- ``all done, coverage ≥ 0.95``: every run ended ``done`` with coverage at least
  ``COVERAGE_MIN`` (a run with no report, or one that timed out, fails it);
- ``no robot contact``: no robot–robot contact in any run;
- ``makespan ≤ local``: the median, over the (member, seed) pairs both modes finished, of the
  mode's makespan over local's is at most 1 (local itself has no such check).

The mode's verdict is PASS when every check it has passes.
"""

from __future__ import annotations

from typing import Any

import numpy as np

COVERAGE_MIN = 0.95
BASELINE = "local"
CHECKS = ("no unreachable", "all done, coverage ≥ 0.95", "no robot contact", "makespan ≤ local")


def family_run(figures: dict[str, Any]) -> dict[str, Any]:
    """One run's row: member, mode, seed, status, coverage, contacts, makespan, unreachable
    events and given-up waypoints (None where the run left no report)."""
    member, _, mode = figures["world"].rpartition("/")
    reported = figures["status"] != "no report"
    contacts = figures.get("contacts") or {}
    return {
        "member": member,
        "mode": mode,
        "seed": figures["seed"],
        "status": figures["status"],
        "coverage": figures.get("coverage"),
        "robot_contacts": contacts.get("robot_robot") if reported else None,
        "wall_contacts": contacts.get("robot_wall") if reported else None,
        "makespan_s": figures.get("makespan_s"),
        "unreachable": figures.get("unreachable") if reported else None,
        "given_up": figures.get("skipped_waypoints"),
        "run_dir": figures.get("run_dir"),
    }


def _makespan_ratio(runs: list[dict[str, Any]], mode: str) -> float | None:
    """The median of ``mode``'s makespan over the baseline's, on the (member, seed) pairs both
    finished; None without such a pair."""
    local = {
        (r["member"], r["seed"]): r["makespan_s"]
        for r in runs
        if r["mode"] == BASELINE and r["status"] == "done" and r["makespan_s"]
    }
    ratios = [
        r["makespan_s"] / local[(r["member"], r["seed"])]
        for r in runs
        if r["mode"] == mode
        and r["status"] == "done"
        and r["makespan_s"]
        and (r["member"], r["seed"]) in local
    ]
    return round(float(np.median(ratios)), 3) if ratios else None


def mode_summary(runs: list[dict[str, Any]], mode: str) -> dict[str, Any]:
    """``mode``'s totals over its runs in ``runs``, its checks and its verdict."""
    mine = [r for r in runs if r["mode"] == mode]
    done = [r for r in mine if r["status"] == "done"]
    coverages = [r["coverage"] for r in mine if r["coverage"] is not None]
    makespans = [r["makespan_s"] for r in done if r["makespan_s"]]
    unreachable = sum(len(r["unreachable"] or ()) for r in mine)
    robot_contacts = sum(r["robot_contacts"] or 0 for r in mine)
    ratio = _makespan_ratio(runs, mode) if mode != BASELINE else None
    checks: dict[str, bool | None] = {
        "no unreachable": unreachable == 0,
        "all done, coverage ≥ 0.95": bool(mine)
        and len(done) == len(mine)
        and all(r["coverage"] is not None and r["coverage"] >= COVERAGE_MIN for r in mine),
        "no robot contact": robot_contacts == 0,
        "makespan ≤ local": None if mode == BASELINE else (ratio is not None and ratio <= 1.0),
    }
    return {
        "runs": len(mine),
        "finished": len(done),
        "unreachable": unreachable,
        "coverage_min": min(coverages, default=None),
        "robot_contacts": robot_contacts,
        "wall_contacts": sum(r["wall_contacts"] or 0 for r in mine),
        "makespan_s_median": round(float(np.median(makespans)), 1) if makespans else None,
        "makespan_over_local_median": ratio,
        "given_up": sum(r["given_up"] or 0 for r in mine),
        "checks": checks,
        "verdict": "PASS" if all(v is not False for v in checks.values()) else "FAIL",
    }


def family_summary(runs: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Every mode's :func:`mode_summary`, in the order the modes first appear."""
    return {mode: mode_summary(runs, mode) for mode in dict.fromkeys(r["mode"] for r in runs)}
