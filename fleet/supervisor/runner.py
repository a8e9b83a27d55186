"""A `fleet up` run in the background, for benchmarks and integration tests: its process table,
the coordinator's events as they are written, its sim clock, and cleanup of every process it
started.

Its waits (:meth:`RunningFleet.wait`, :meth:`RunningFleet.finish`) guard against a hung run by
its sim clock (:class:`fleet.sim_guard.SimGuard`): past its wall bound, a wait goes on while
the sim clock moves, up to the sim time the run would make in that bound on an idle machine
(``IDLE_RTF``, or ``--speed``), and gives up once the clock has stalled for ``STALL_S``. A run
slowed down by a busy machine is waited for; a hung one is not, and no wait ends sooner than
its wall bound."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import tempfile
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
from fleet.sim_guard import SimGuard

EVENT_COLUMNS = ("seq", "wall", "sim", "kind", "robot", "task", "detail")
# a wait past its wall bound gives up once the sim clock has not moved for this long (wall s)
STALL_S = 30.0
# sim seconds per wall second of a fleet at --speed 0 on an idle 2-core machine at its fastest
# (5.7-6.3 with 3 robots on home in BENCHMARKS.md's batches; today's agents make 2.5 on home
# and 3.3-3.9 on small, "Where a fleet run's time goes"): a wait's sim budget is its wall bound
# times this, so it is generous, never what cuts a slow run short
IDLE_RTF = 6.0
# fleet up writes its process table at its start; it is waited for this long (wall s)
TABLE_WAIT_S = 30.0


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
    runs until it is stopped; with ``command`` ``("explore",)``, ``fleet explore --headless``."""

    def __init__(
        self,
        run_dir: Path,
        world: str,
        robots: int = 3,
        seed: int = 0,
        timeout_s: float | None = None,
        cwd: Path | None = None,
        speed: float = 0.0,
        options: Sequence[str] = (),
        loop: bool = False,
        command: Sequence[str] = ("up",),
    ) -> None:
        """``timeout_s``: fleet up's ``--timeout``, a wall budget (None: none; :meth:`finish`
        guards against a hung run by its sim clock); ``options``: more options of ``fleet up``
        (e.g. ``--deconfliction cbs``)."""
        self.dir = run_dir
        cmd = [
            sys.executable,
            "-m",
            "fleet.cli",
            *command,
            "--robots",
            str(robots),
            "--world",
            world,
            "--headless",
            *(("--loop" if loop else "--until-done",) if command[0] == "up" else ()),
            *(() if timeout_s is None else ("--timeout", str(timeout_s))),
            "--speed",
            str(speed),
            "--seed",
            str(seed),
            "--run-dir",
            str(run_dir),
            *options,
        ]
        # to a file, not a pipe: nobody reads fleet up's output while it runs, and a pipe's
        # buffer (64 KiB) fills in a long run and blocks fleet up on its next progress line
        self._out = tempfile.TemporaryFile()  # noqa: SIM115 - closed in cleanup
        self.proc = subprocess.Popen(cmd, stdout=self._out, stderr=subprocess.STDOUT, cwd=cwd)
        self.speed = speed
        self.children: set[int] = set()
        self.output = ""
        self.left: list[int] = []
        self._clock: SimClock | None = None

    def events(self, kind: str | None = None, robot: str | None = None) -> list[dict[str, Any]]:
        return [
            e
            for e in read_events(self.dir / "coordinator.sqlite")
            if (kind is None or e["kind"] == kind) and (robot is None or e["robot"] == robot)
        ]

    def first_award(self, robot: str | None = None) -> float | None:
        """The sim time of the job's first award (to ``robot``, if named); None before it. A
        moment of the job is counted from here, not from the sim clock's start: the clock runs
        while the agents start, which takes longer on a busy machine."""
        awards = self.events("awarded", robot)
        return awards[0]["sim"] if awards else None

    def clock(self) -> SimClock:
        """The run's sim clock, heard from once the process table is written (the one clock
        of this run: closed by :meth:`cleanup`)."""
        if self._clock is None:
            self._clock = SimClock(self)
        return self._clock

    def sim_t(self) -> float:
        """The run's sim time as heard so far; 0 before its clock can be heard (no process
        table, or no router to hear it through yet)."""
        if self._clock is None and not (self.dir / "processes.json").exists():
            return 0.0
        try:
            return self.clock().t
        except Exception:  # zenoh raises ZError while the run's router is not up yet
            return 0.0

    def guard(self, wall_s: float, sim_s: float | None = None) -> SimGuard:
        """A guard for a wait of ``wall_s`` wall seconds on this run: past them, it goes on
        while the sim clock moves, up to ``sim_s`` sim seconds (by default what the run would
        make in ``wall_s`` at its speed, or at ``IDLE_RTF`` with --speed 0)."""
        budget = sim_s if sim_s is not None else wall_s * (self.speed or IDLE_RTF)
        return SimGuard(self.sim_t, wall_s, min(wall_s, STALL_S) or STALL_S, budget)

    def wait(
        self,
        pred: Callable[[], Any],
        timeout: float,
        poll: float = 0.05,
        sim_s: float | None = None,
    ) -> bool:
        """Poll ``pred()`` until it is truthy (True) or the run ends, or :meth:`guard`
        ``(timeout, sim_s)`` gives up."""
        guard = self.guard(timeout, sim_s)
        while not guard.expired():
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
        """Wait for ``fleet up`` to end (:meth:`guard` ``(timeout)`` bounds the wait), clean
        up, and return its report (None if none)."""
        guard = self.guard(timeout)
        while self.proc.poll() is None and not guard.expired():
            self.children.update(descendants(self.proc.pid))
            time.sleep(0.5)
        self.cleanup()
        report = self.dir / "report.json"
        return json.loads(report.read_text()) if report.exists() else None

    def cleanup(self) -> list[int]:
        """Stop ``fleet up`` if it still runs, and kill (and return) any process it left."""
        if self._clock is not None:
            self._clock.close()
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(60)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if not self._out.closed:
            self._out.seek(0)
            self.output = self._out.read().decode(errors="replace")
            self._out.close()
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
        """Heard from once ``fleet``'s process table is written (``TABLE_WAIT_S`` at most: it
        is written as fleet up starts, before any sim clock runs)."""
        deadline = time.monotonic() + TABLE_WAIT_S
        while not (fleet.dir / "processes.json").exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        table = fleet.table()
        cfg = load_fleet_config()
        self._clock = BelievedClock(clock_step_s(cfg.sim, cfg.agent), lambda _n, _why: None)
        self.bus = Bus("dashboard", f"bench-{id(self)}", [table["endpoint"]], table["fleet"])
        self.bus.subscribe(self.bus.keys.clock(), Clock, self._on_clock)
        self.closed = False

    @property
    def t(self) -> float:
        return self._clock.now

    def _on_clock(self, _key: str, msg: Clock) -> None:
        self._clock.hear(msg.stamp)

    def close(self) -> None:
        """Stop hearing the clock (again: nothing)."""
        if not self.closed:
            self.closed = True
            self.bus.close()
