"""`fleet bench repetition`: where the repetition of real runs comes from, run by run and per
world, live against the tour alone (the analysis is :mod:`fleet.report.repetition`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fleet.report.repetition import (
    CAUSE_LABELS,
    CAUSES,
    ELEMENTS,
    GROUP_LABELS,
    GROUPS,
    KINDS,
    breakdown,
)
from fleet.report.summary import REPORT_FILE, ReportError


def run_dirs(paths: Sequence[Path]) -> list[Path]:
    """The run dirs named by ``paths``: a run dir itself (it holds report.json), or a
    directory of run dirs (``fleet bench fleet --run-root``), in name order."""
    found: list[Path] = []
    for p in paths:
        if (p / REPORT_FILE).is_file():
            found.append(p)
        elif p.is_dir():
            runs = sorted(d for d in p.iterdir() if (d / REPORT_FILE).is_file())
            if not runs:
                raise ReportError(f"{p}: neither a run dir (no {REPORT_FILE}) nor a dir of runs")
            found.extend(runs)
        else:
            raise ReportError(f"no such run dir: {p}")
    return found


def _median(values: Sequence[float]) -> float:
    return round(float(np.median(values)), 3)


def bench_repetition(
    paths: Sequence[Path],
    subdivide: int = 1,
    progress: Callable[[str], None] = lambda _line: None,
) -> dict[str, Any]:
    """The breakdown of every run (:func:`fleet.report.repetition.breakdown`, its grid's cells
    cut ``subdivide`` × ``subdivide``), and per world the medians over its runs (the tour's
    breakdown is the first run's: every run of a world plans the same tour)."""
    runs = []
    for d in run_dirs(paths):
        runs.append(breakdown(d, subdivide))
        r = runs[-1]
        progress(
            f"{d}: repetition {r['repetition']:.1f} (replay {r['replay_repetition']:.1f}); "
            f"the tour alone {r['tour']['repetition']:.1f}"
        )
    worlds: dict[str, Any] = {}
    for name in dict.fromkeys(r["world"] for r in runs):
        mine = [r for r in runs if r["world"] == name]
        worlds[name] = {
            "runs": len(mine),
            "repetition": _median([r["repetition"] for r in mine]),
            "replay_repetition": _median([r["replay_repetition"] for r in mine]),
            "causes": {c: _median([r["causes"][c] for r in mine]) for c in CAUSES},
            "groups": {g: _median([r["groups"][g] for r in mine]) for g in GROUPS},
            "kinds": {k: _median([r["kinds"][k] for r in mine]) for k in KINDS},
            "elements": {e: _median([r["elements"][e] for r in mine]) for e in ELEMENTS},
            "tour": mine[0]["tour"],
        }
    return {"subdivide": subdivide, "runs": runs, "worlds": worlds}


def table_lines(result: dict[str, Any]) -> list[str]:
    """Per world a Markdown table: each cause in points of repetition, per run, the median,
    and the tour alone; then the totals, and the medians by step kind."""
    lines: list[str] = []
    for name, w in result["worlds"].items():
        mine = [r for r in result["runs"] if r["world"] == name]
        heads = [f"seed {r['seed']}" for r in mine]
        lines += [
            f"{name}: {w['runs']} run(s); points of repetition on "
            f"{100 * mine[0]['cell_m']:g} cm cells",
            "",
            "| cause | " + " | ".join(heads) + " | median | the tour alone |",
            "| --- |" + " --- |" * (len(heads) + 2),
        ]
        for c in CAUSES:
            live = [r["causes"][c] for r in mine]
            plan = w["tour"]["causes"][c]
            if max(*live, plan) < 0.05:
                continue
            cells = " | ".join(f"{v:.1f}" for v in live)
            lines.append(f"| {CAUSE_LABELS[c]} | {cells} | {w['causes'][c]:.1f} | {plan:.1f} |")
        total = " | ".join(f"{r['replay_repetition']:.1f}" for r in mine)
        sim = " | ".join(f"{r['repetition']:.1f}" for r in mine)
        lines += [
            f"| **sum (replayed tracks)** | {total} | {w['replay_repetition']:.1f} | "
            f"{w['tour']['repetition']:.1f} |",
            f"| simulator (report.json) | {sim} | {w['repetition']:.1f} | "
            f"{w['tour']['own'].get('repetition', float('nan')) * 100:.1f} (own grid) |",
            "",
            "| by what would remove it | " + " | ".join(heads) + " | median | the tour alone |",
            "| --- |" + " --- |" * (len(heads) + 2),
        ]
        for g in GROUPS:
            cells = " | ".join(f"{r['groups'][g]:.1f}" for r in mine)
            lines.append(
                f"| {GROUP_LABELS[g]} | {cells} | {w['groups'][g]:.1f} | "
                f"{w['tour']['groups'][g]:.1f} |"
            )
        lines += [
            "",
            "  by step kind (median): "
            + ", ".join(f"{k} {v:.1f}" for k, v in w["kinds"].items() if v >= 0.05),
            "",
        ]
    return lines
