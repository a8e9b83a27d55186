"""`fleet bench soak`: one long run of the same job, looped, and whether the fleet's processes
hold their memory and open files and the run dir its size.

The run is ``fleet up --headless --loop`` (:class:`fleet.supervisor.runner.RunningFleet`): the
coordinator starts the job again each time it finishes. Every ``every_s`` sim seconds the bench
samples (:func:`sample`) each process of the run's table and ``fleet up`` itself: its resident
memory (``VmRSS`` of ``/proc/PID/status``) and its open files (the entries of
``/proc/PID/fd``); and the run dir's size on disk, and the jobs finished so far. At ``sim_s``
it stops ``fleet up`` (SIGTERM: the report is written as after Ctrl-C).

The verdict (:func:`verdict`), against the issue's targets, after a warm-up of ``warmup_s``
sim seconds (the first job's planning, SLAM maps filling up, the allocator's pools):

- memory: each process's RSS level at the end at most ``Targets.rss_growth`` above its level
  just past the warm-up, each level the median of the samples over ``Targets.level_span_s``
  (the first that long past the warm-up, the last that long before the end): a process that
  allocates ten megabytes for a second (a pose-graph optimization, a job's planning) and gives
  them back shows in one sample, not in its level, while a leak moves the level. The growth
  between the single first and last samples is reported beside it;
- open files: no growth: the most open in the later half of the samples past the warm-up
  is at most the most open in the earlier half (a leak of one file per job shows as a rise);
- run dir: bounded: past the warm-up it grows by at most ``Targets.dir_mb_per_h`` megabytes
  per sim hour (logs and the coordinator's event and bid tables grow with every job; a day
  looped stays under a day's worth of that).

A process that was restarted during the run (its pid changed) is named and judged on its
samples since.
"""

from __future__ import annotations

import json
import math
import os
import signal
import sqlite3
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from fleet.rundir import read_table
from fleet.supervisor.runner import RunningFleet

# the file the bench writes its result to, in the run dir (not counted in the dir's size)
RESULT_FILE = "soak.json"
# each sample is waited for this long (wall s) at least, and on while the sim clock moves
# (the first longer: fleet up starts its processes and the coordinator plans the job)
SAMPLE_WAIT_S = 120.0
START_WAIT_S = 600.0
# fleet up writes its report after SIGTERM; it is waited for this long (wall s)
STOP_WAIT_S = 900.0
POLL_S = 0.5


@dataclass(frozen=True)
class Targets:
    """The issue's targets: RSS growth past the warm-up (a fraction), the run dir's growth
    past it (MB per sim hour), and the warm-up (sim s)."""

    rss_growth: float = 0.05
    dir_mb_per_h: float = 50.0
    warmup_s: float = 600.0
    level_span_s: float = 300.0


@dataclass(frozen=True)
class Sample:
    """One look at the run: sim and wall time (s since the start), per process its pid, RSS
    (kB) and open files (None when it was gone), the run dir's bytes, the jobs finished."""

    sim_s: float
    wall_s: float
    pid: dict[str, int]
    rss_kb: dict[str, int | None]
    fds: dict[str, int | None]
    dir_bytes: int
    jobs: int


def rss_kb(pid: int) -> int | None:
    """Resident memory of process ``pid`` in kB (``VmRSS``); None when it is gone."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return None
    for line in text.splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return None


def open_files(pid: int) -> int | None:
    """Open file descriptors of process ``pid``; None when it is gone."""
    try:
        return len(os.listdir(f"/proc/{pid}/fd"))
    except OSError:
        return None


def dir_bytes(path: Path, skip: Sequence[str] = (RESULT_FILE,)) -> int:
    """Bytes of the files under ``path`` (the names in ``skip`` left out)."""
    total = 0
    for root, _dirs, files in os.walk(path):
        for name in files:
            if name in skip:
                continue
            try:
                total += os.lstat(os.path.join(root, name)).st_size
            except OSError:
                continue
    return total


def jobs_finished(state: Path) -> int:
    """How many jobs the coordinator's state file says have finished (0 before it exists)."""
    if not state.exists():
        return 0
    try:
        db = sqlite3.connect(f"file:{state}?mode=ro", uri=True, timeout=5)
        try:
            query = "SELECT count(*) FROM events WHERE kind = 'finished'"
            return int(db.execute(query).fetchone()[0])
        finally:
            db.close()
    except sqlite3.Error:
        return 0


def pids_of(run_dir: Path) -> dict[str, int]:
    """``fleet up`` (as ``up``) and every process of its table, by name."""
    table = read_table(run_dir)
    return {"up": table.up_pid} | {name: p.pid for name, p in table.processes.items()}


def sample(run_dir: Path, sim_s: float, wall_s: float) -> Sample:
    """One look at the run in ``run_dir`` at ``sim_s`` (``wall_s`` since the bench began)."""
    pids = pids_of(run_dir)
    return Sample(
        round(sim_s, 1),
        round(wall_s, 1),
        pids,
        {n: rss_kb(p) for n, p in pids.items()},
        {n: open_files(p) for n, p in pids.items()},
        dir_bytes(run_dir),
        jobs_finished(run_dir / "coordinator.sqlite"),
    )


def _since_pid(samples: Sequence[Sample], name: str) -> list[Sample]:
    """The samples of ``name``'s last process (since its last restart), where it was alive."""
    last = samples[-1].pid.get(name)
    return [s for s in samples if s.pid.get(name) == last and s.rss_kb.get(name) is not None]


def process_verdict(samples: Sequence[Sample], name: str, targets: Targets) -> dict[str, Any]:
    """One process's memory and open files past the warm-up, judged (see the module)."""
    mine = _since_pid(samples, name)
    past = [s for s in mine if s.sim_s >= targets.warmup_s]
    out: dict[str, Any] = {"restarted": len(mine) < len([s for s in samples if name in s.pid])}
    if len(past) < 2:
        return out | {"judged": False}
    rss = [(s.sim_s, s.rss_kb[name] or 0) for s in past]
    span = targets.level_span_s
    first = statistics.median(kb for t, kb in rss if t <= rss[0][0] + span)
    last = statistics.median(kb for t, kb in rss if t >= rss[-1][0] - span)
    fds = [s.fds[name] for s in past if s.fds.get(name) is not None]
    half = len(fds) // 2
    fds_grew = bool(fds[:half]) and max(fds[half:]) > max(fds[:half])
    growth = last / first - 1 if first else 0.0
    return out | {
        "judged": True,
        "rss_mb_at_warmup": round(first / 1024, 1),
        "rss_mb_at_end": round(last / 1024, 1),
        "rss_mb_peak": round(max(s.rss_kb[name] or 0 for s in mine) / 1024, 1),
        "rss_growth": round(growth, 4),
        "rss_growth_last_sample": round(rss[-1][1] / rss[0][1] - 1, 4) if rss[0][1] else 0.0,
        "fds_min": min(fds),
        "fds_max": max(fds),
        "fds_grew": fds_grew,
        "ok": growth <= targets.rss_growth and not fds_grew,
    }


def dir_verdict(samples: Sequence[Sample], targets: Targets) -> dict[str, Any]:
    """The run dir's size over time, and its growth past the warm-up (MB per sim hour)."""
    past = [s for s in samples if s.sim_s >= targets.warmup_s]
    out: dict[str, Any] = {
        "mb_over_time": [[s.sim_s, round(s.dir_bytes / 1e6, 2)] for s in samples],
    }
    if len(past) < 2 or past[-1].sim_s <= past[0].sim_s:
        return out | {"judged": False}
    rate = (past[-1].dir_bytes - past[0].dir_bytes) / 1e6 / (past[-1].sim_s - past[0].sim_s)
    per_h = rate * 3600
    return out | {
        "judged": True,
        "mb_per_sim_h": round(per_h, 2),
        "ok": per_h <= targets.dir_mb_per_h,
    }


def verdict(samples: Sequence[Sample], targets: Targets) -> dict[str, Any]:
    """Every process's verdict, the run dir's, and whether all were judged and passed."""
    names = sorted({n for s in samples for n in s.pid})
    procs = {n: process_verdict(samples, n, targets) for n in names}
    run_dir = dir_verdict(samples, targets)
    judged = [*procs.values(), run_dir]
    return {
        "targets": asdict(targets),
        "processes": procs,
        "run_dir": run_dir,
        "ok": bool(judged) and all(v["judged"] and v["ok"] for v in judged),
    }


def _line(s: Sample, sim_s: float) -> str:
    """A progress line: where the run is, each process's RSS (MB) and open files."""
    procs = " ".join(
        f"{n} {(s.rss_kb[n] or 0) / 1024:.0f}/{s.fds[n] if s.fds[n] is not None else '-'}"
        for n in sorted(s.pid)
    )
    rate = s.sim_s / s.wall_s if s.wall_s else 0.0
    return (
        f"sim {s.sim_s:.0f}/{sim_s:.0f} s, wall {s.wall_s:.0f} s ({rate:.2f}x), jobs {s.jobs}, "
        f"run dir {s.dir_bytes / 1e6:.1f} MB; RSS MB/open files: {procs}"
    )


def _await_sim(fleet: RunningFleet, at_s: float, wall_s: float) -> str:
    """Wait until the sim clock reaches ``at_s``: ``wall_s`` at least, and on while the clock
    moves; why not, if it does not ('' when it does)."""
    if fleet.wait(lambda: fleet.sim_t() >= at_s, wall_s, poll=POLL_S, sim_s=math.inf):
        return ""
    if fleet.proc.poll() is not None:
        return f"fleet up exited with code {fleet.proc.returncode} at {fleet.sim_t():.1f} s sim"
    return f"the sim clock stopped at {fleet.sim_t():.1f} s sim"


def run_soak(
    run_dir: Path,
    world: str,
    robots: int,
    seed: int,
    speed: float,
    sim_s: float,
    every_s: float,
    targets: Targets,
    progress: Callable[[str], None],
) -> dict[str, Any]:
    """The soak: ``fleet up --loop`` sampled every ``every_s`` sim s until ``sim_s``, then
    stopped; its samples and verdict, also written to ``run_dir/soak.json`` at each sample."""
    t0 = time.monotonic()
    result: dict[str, Any] = {
        "world": world,
        "robots": robots,
        "seed": seed,
        "speed": speed,
        "sim_s": sim_s,
        "every_s": every_s,
        "run_dir": str(run_dir),
        "stopped": "",
    }
    samples: list[Sample] = []
    fleet = RunningFleet(run_dir, world, robots, seed, speed=speed, loop=True)
    try:
        at = 0.0
        while at < sim_s and not result["stopped"]:
            wall_s = SAMPLE_WAIT_S if samples else START_WAIT_S
            at = min(at + every_s, sim_s)
            result["stopped"] = _await_sim(fleet, at, wall_s)
            if not result["stopped"]:
                samples.append(sample(run_dir, fleet.sim_t(), time.monotonic() - t0))
                progress(_line(samples[-1], sim_s))
                _write(run_dir, result, samples, targets)
        progress("stopping fleet up (it writes its report)")
        fleet.proc.send_signal(signal.SIGTERM)
        report = fleet.finish(STOP_WAIT_S) or {}
    finally:
        fleet.cleanup()
    result["stop_wall_s"] = round(time.monotonic() - t0 - (samples[-1].wall_s if samples else 0), 1)
    result["report"] = {k: report.get(k) for k in ("status", "coverage", "collisions")}
    result["left_processes"] = fleet.left
    return _write(run_dir, result, samples, targets)


def _write(
    run_dir: Path, result: dict[str, Any], samples: list[Sample], targets: Targets
) -> dict[str, Any]:
    out = result | {"samples": [asdict(s) for s in samples], "verdict": verdict(samples, targets)}
    (run_dir / RESULT_FILE).write_text(json.dumps(out, indent=1))
    return out


def table_lines(result: dict[str, Any]) -> list[str]:
    """The verdict as a table: per process, then the run dir, then the whole."""
    v = result["verdict"]
    t = v["targets"]
    lines = [
        f"{result['robots']} robots, {result['world']}, {result['sim_s']:.0f} s sim at "
        f"--speed {result['speed']}; warm-up {t['warmup_s']:.0f} s sim"
        + (f"; stopped early: {result['stopped']}" if result["stopped"] else ""),
        "process       RSS MB at warm-up  at end  peak  growth  open files min-max  verdict",
    ]
    for name, p in v["processes"].items():
        if not p["judged"]:
            lines.append(f"{name:<12}  not judged (too few samples past the warm-up)")
            continue
        lines.append(
            f"{name:<12}  {p['rss_mb_at_warmup']:>17}  {p['rss_mb_at_end']:>6}  "
            f"{p['rss_mb_peak']:>4}  {100 * p['rss_growth']:>5.1f}%  "
            f"{p['fds_min']:>11}-{p['fds_max']:<7}  {'ok' if p['ok'] else 'FAIL'}"
            + ("  (restarted)" if p["restarted"] else "")
        )
    d = v["run_dir"]
    sizes = ", ".join(
        f"{mb} MB at {s:.0f} s"
        for s, mb in d["mb_over_time"][:: max(1, len(d["mb_over_time"]) // 6)]
    )
    grows = f"{d['mb_per_sim_h']} MB per sim hour past the warm-up" if d["judged"] else "not judged"
    lines.append(f"run dir: {sizes}; {grows} (target <= {t['dir_mb_per_h']})")
    lines.append(f"verdict: {'pass' if v['ok'] else 'FAIL'}")
    return lines
