"""A `fleet up` run in the background, for benchmarks and integration tests: its process table,
the coordinator's events as they are written, and cleanup of every process it started."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from fleet.bus import Bus
from fleet.params import load_fleet_config
from fleet.plausible import SimClock as BelievedClock
from fleet.plausible import clock_step_s
from fleet.protocol import Clock
from fleet.rundir import RunDirError, process_state, read_table

EVENT_COLUMNS = ("seq", "wall", "sim", "kind", "robot", "task", "detail")


def descendants(pid: int) -> list[int]:
    """Every process whose parent chain leads to ``pid`` (read from /proc)."""
    parents = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
            except OSError:
                continue
            parents[int(entry)] = int(stat.rsplit(")", 1)[1].split()[1])
    out, frontier = [], [pid]
    while frontier:
        p = frontier.pop()
        kids = [c for c, pp in parents.items() if pp == p]
        out += kids
        frontier += kids
    return out


def read_events(state: Path) -> list[dict[str, Any]]:
    """The events in a coordinator's state file so far (none before it exists)."""
    if not state.exists():
        return []
    try:
        db = sqlite3.connect(f"file:{state}?mode=ro", uri=True, timeout=5)
        try:
            rows = db.execute(
                f"SELECT {', '.join(EVENT_COLUMNS)} FROM events ORDER BY seq"
            ).fetchall()
        finally:
            db.close()
    except sqlite3.OperationalError:
        return []
    return [dict(zip(EVENT_COLUMNS, r, strict=True)) for r in rows]


class RunningFleet:
    """``fleet up --headless --until-done --speed S`` (0 by default) started at construction;
    with ``loop``, ``fleet up --headless --loop`` (the job again each time it finishes), which
    runs until it is stopped."""

    def __init__(
        self,
        run_dir: Path,
        world: str,
        robots: int = 3,
        seed: int = 0,
        timeout_s: float | None = 900.0,
        cwd: Path | None = None,
        speed: float = 0.0,
        options: Sequence[str] = (),
        loop: bool = False,
    ) -> None:
        """``timeout_s``: fleet up's ``--timeout`` (None: none); ``options``: more options of
        ``fleet up`` (e.g. ``--deconfliction cbs``)."""
        self.dir = run_dir
        cmd = [
            sys.executable,
            "-m",
            "fleet.cli",
            "up",
            "--robots",
            str(robots),
            "--world",
            world,
            "--headless",
            "--loop" if loop else "--until-done",
            *(() if timeout_s is None else ("--timeout", str(timeout_s))),
            "--speed",
            str(speed),
            "--seed",
            str(seed),
            "--run-dir",
            str(run_dir),
            *options,
        ]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, cwd=cwd)
        self.children: set[int] = set()
        self.output = ""
        self.left: list[int] = []

    def events(self, kind: str | None = None, robot: str | None = None) -> list[dict[str, Any]]:
        return [
            e
            for e in read_events(self.dir / "coordinator.sqlite")
            if (kind is None or e["kind"] == kind) and (robot is None or e["robot"] == robot)
        ]

    def wait(self, pred: Callable[[], Any], timeout: float, poll: float = 0.05) -> bool:
        """Poll ``pred()`` until it is truthy (True) or ``timeout`` passes or the run ends."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.children.update(descendants(self.proc.pid))
            if pred():
                return True
            if self.proc.poll() is not None:
                return bool(pred())
            time.sleep(poll)
        return False

    def table(self) -> dict[str, Any]:
        return json.loads((self.dir / "processes.json").read_text())

    def signal(self, name: str, sig: int) -> float:
        """Send ``sig`` to process ``name`` of the run (checked to be ours); the Unix time."""
        table = read_table(self.dir)
        record = table.processes[name]
        if process_state(record.pid, record.argv) == "gone":
            raise RunDirError(f"{name} (pid {record.pid}) is gone")
        sent = time.time()
        os.kill(record.pid, sig)
        return sent

    def verb(self, *args: str) -> subprocess.CompletedProcess:
        """``fleet <args> --run-dir <this run>`` as a user types it."""
        return subprocess.run(
            [sys.executable, "-m", "fleet.cli", *args, "--run-dir", str(self.dir)],
            capture_output=True,
            text=True,
            timeout=60,
        )

    def finish(self, timeout: float = 900.0) -> dict[str, Any] | None:
        """Wait for ``fleet up`` to end, clean up, and return its report (None if none)."""
        deadline = time.monotonic() + timeout
        while self.proc.poll() is None and time.monotonic() < deadline:
            self.children.update(descendants(self.proc.pid))
            time.sleep(0.5)
        self.cleanup()
        report = self.dir / "report.json"
        return json.loads(report.read_text()) if report.exists() else None

    def cleanup(self) -> list[int]:
        """Stop ``fleet up`` if it still runs, and kill (and return) any process it left."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(60)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.proc.stdout is not None and not self.proc.stdout.closed:
            self.output = self.proc.stdout.read().decode(errors="replace")
            self.proc.stdout.close()
        time.sleep(1.0)
        left = [p for p in self.children if Path(f"/proc/{p}").exists()]
        for p in left:
            os.kill(p, signal.SIGKILL)
        self.left += left
        return left


class SimClock:
    """The run's sim time, from its clock messages, believed a clock step at a time
    (:class:`fleet.plausible.SimClock`): a forged clock message does not fire a bench's
    failures early."""

    def __init__(self, fleet: RunningFleet) -> None:
        fleet.wait(lambda: (fleet.dir / "processes.json").exists(), 30.0)
        table = fleet.table()
        cfg = load_fleet_config()
        self._clock = BelievedClock(clock_step_s(cfg.sim, cfg.agent), lambda _n, _why: None)
        self.bus = Bus("dashboard", f"bench-{id(self)}", [table["endpoint"]], table["fleet"])
        self.bus.subscribe(self.bus.keys.clock(), Clock, self._on_clock)

    @property
    def t(self) -> float:
        return self._clock.now

    def _on_clock(self, _key: str, msg: Clock) -> None:
        self._clock.hear(msg.stamp)

    def close(self) -> None:
        self.bus.close()
