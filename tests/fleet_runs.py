"""A real `fleet up` in the background for integration tests: its processes, its events, the
operator verbs on it, and cleanup of everything it started."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

WORLDS = Path(__file__).resolve().parents[1] / "configs" / "worlds"


def children_of(pid: int) -> list[int]:
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


class FleetRun:
    """``fleet up --headless --until-done --speed 0`` on a world, started at construction."""

    def __init__(self, run_dir: Path, robots: int = 3, world: str = "small", timeout_s=200.0):
        self.dir = run_dir
        cmd = [
            sys.executable,
            "-m",
            "fleet.cli",
            "up",
            "--robots",
            str(robots),
            "--world",
            str(WORLDS / f"{world}.yaml"),
            "--headless",
            "--until-done",
            "--timeout",
            str(timeout_s),
            "--speed",
            "0",
            "--run-dir",
            str(run_dir),
        ]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        self.children: set[int] = set()
        self.output = ""

    def events(self, kind: str | None = None) -> list[dict]:
        """The coordinator's events so far (none before it has written its state)."""
        path = self.dir / "coordinator.sqlite"
        if not path.exists():
            return []
        try:
            db = sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=5)
            try:
                rows = db.execute(
                    "SELECT seq, wall, sim, kind, robot, task, detail FROM events ORDER BY seq"
                ).fetchall()
            finally:
                db.close()
        except sqlite3.OperationalError:
            return []
        cols = ("seq", "wall", "sim", "kind", "robot", "task", "detail")
        out = [dict(zip(cols, r, strict=True)) for r in rows]
        return [e for e in out if kind is None or e["kind"] == kind]

    def wait_for(self, pred, timeout: float = 120.0, what: str = "") -> None:
        """Poll ``pred()`` until it holds; fail with the fleet's output if it never does."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.children.update(children_of(self.proc.pid))
            if pred():
                return
            if self.proc.poll() is not None:
                break
            time.sleep(0.2)
        raise AssertionError(f"not seen: {what}\n{self.explained()}")

    def verb(self, *args: str) -> subprocess.CompletedProcess:
        """``fleet <args> --run-dir <this run>``, e.g. ``verb("kill", "robot-1", "--signal",
        "KILL")``; fails the test if it does not exit 0."""
        done = subprocess.run(
            [sys.executable, "-m", "fleet.cli", *args, "--run-dir", str(self.dir)],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert done.returncode == 0, f"fleet {' '.join(args)}: {done.stdout}{done.stderr}"
        return done

    def finish(self, timeout: float = 300.0) -> dict:
        """Wait for ``fleet up`` to end; returns its report (collecting its processes meanwhile)."""
        deadline = time.monotonic() + timeout
        while self.proc.poll() is None and time.monotonic() < deadline:
            self.children.update(children_of(self.proc.pid))
            time.sleep(0.5)
        self.cleanup()
        report = self.dir / "report.json"
        assert report.exists(), self.explained()
        return json.loads(report.read_text())

    def cleanup(self) -> list[int]:
        """Stop ``fleet up`` if it still runs, and kill (and return) any process it left."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(60)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.output = self.proc.stdout.read().decode(errors="replace") if self.proc.stdout else ""
        time.sleep(1.0)
        left = [p for p in self.children if Path(f"/proc/{p}").exists()]
        for p in left:
            os.kill(p, signal.SIGKILL)
        return left

    def explained(self) -> str:
        """The report, the events and every warning the processes logged: what a failed run
        needs to be understood from CI's output alone."""
        report = self.dir / "report.json"
        warnings = [
            line
            for log in sorted(self.dir.glob("*.log"))
            for line in log.read_text(errors="replace").splitlines()
            if " WARNING " in line or " ERROR " in line
        ]
        events = [
            f"{e['sim']:.1f} {e['kind']} {e['robot']} {e['task']} {e['detail']}"
            for e in self.events()
        ]
        text = report.read_text() if report.exists() else "(no report)"
        return "\n".join([text, *events, *warnings, self.output])
