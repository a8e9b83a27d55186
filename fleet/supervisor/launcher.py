"""Starting and stopping the fleet's OS processes, each with its own log file.

Children run ``python -m fleet.cli <command>`` in their own session (so a terminal Ctrl-C
reaches only ``fleet up``, which then stops them in order) and get SIGTERM from the kernel if
``fleet up`` itself dies (Linux ``PR_SET_PDEATHSIG``), so no process outlives the run.

Each start and restart is recorded (:class:`fleet.rundir.ProcessRecord`) and handed to an
``on_change`` callback, which ``fleet up`` uses to rewrite the run dir's process table. A
restarted process appends to its log, so the log of the one before it is kept.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

from fleet.rundir import ProcessRecord

PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


def free_port(host: str = "127.0.0.1") -> int:
    with socket.socket() as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def wait_for_port(host: str, port: int, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with socket.socket() as s:
            s.settimeout(0.2)
            if s.connect_ex((host, port)) == 0:
                return True
        time.sleep(0.05)
    return False


def cpu_ticks(pid: int) -> int | None:
    """The CPU time process ``pid`` has used, user and system, in clock ticks; None when there
    is no such process."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    # the fields after the command name: state is the 3rd field of the line, utime the 14th
    fields = stat.rsplit(")", 1)[1].split()
    return int(fields[11]) + int(fields[12])


class WorkWatch:
    """Whether a process is at work: alive, and using CPU since it was last looked at. A
    starved process is slow but works; a dead, stopped or blocked one does not."""

    def __init__(self, proc: subprocess.Popen) -> None:
        self.proc = proc
        self.ticks = cpu_ticks(proc.pid)

    def alive(self) -> bool:
        return self.proc.poll() is None

    def working(self) -> bool:
        if self.proc.poll() is not None:
            return False
        ticks = cpu_ticks(self.proc.pid)
        moved = ticks is not None and self.ticks is not None and ticks > self.ticks
        self.ticks = ticks
        return moved


class Launcher:
    """The processes of one run, in start order."""

    def __init__(
        self,
        run_dir: Path,
        on_change: Callable[[dict[str, ProcessRecord]], None] | None = None,
    ) -> None:
        self.run_dir = run_dir
        self.procs: dict[str, subprocess.Popen] = {}
        self.records: dict[str, ProcessRecord] = {}
        self._on_change = on_change
        self._logs: dict[str, BinaryIO] = {}
        self._lock = threading.RLock()
        self._stopped = False

    def start(self, name: str, args: list[str]) -> subprocess.Popen:
        """Start ``python -m fleet.cli *args`` as ``name``, logging to ``run_dir/name.log``."""
        with self._lock:
            if name in self.procs:
                raise ValueError(f"{name} was started already; restart it instead")
            return self._spawn(name, args, restarts=0, log_mode="wb")

    def restart(self, name: str, args: list[str]) -> subprocess.Popen:
        """Start ``name`` again with ``args`` once it has exited; its log is appended to."""
        with self._lock:
            if self._stopped:
                raise RuntimeError("the fleet is stopping")
            proc = self.procs.get(name)
            if proc is None:
                raise ValueError(f"no process {name!r} in this run")
            if proc.poll() is None:
                raise RuntimeError(f"{name} is alive (pid {proc.pid}); kill it first")
            self._logs.pop(name).close()
            return self._spawn(name, args, self.records[name].restarts + 1, log_mode="ab")

    def _spawn(self, name: str, args: list[str], restarts: int, log_mode: str) -> subprocess.Popen:
        log_name = f"{name}.log"
        log = open(self.run_dir / log_name, log_mode)  # noqa: SIM115 - closed in stop_all
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        try:
            proc = subprocess.Popen(
                [sys.executable, "-m", "fleet.cli", *args],
                stdout=log,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                start_new_session=True,
                preexec_fn=_die_with_parent,
                env=env,
            )
        except BaseException:
            log.close()
            raise
        self._logs[name] = log
        self.procs[name] = proc
        self.records[name] = ProcessRecord(proc.pid, list(args), time.time(), restarts, log_name)
        if self._on_change is not None:
            self._on_change(dict(self.records))
        return proc

    def dead(self) -> dict[str, int]:
        """Processes that have exited, with their exit codes."""
        with self._lock:
            return {n: p.returncode for n, p in self.procs.items() if p.poll() is not None}

    def stop(self, name: str, sig: int = signal.SIGTERM, timeout: float = 5.0) -> None:
        with self._lock:
            proc = self.procs.get(name)
        if proc is None or proc.poll() is not None:
            return
        proc.send_signal(sig)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()

    def stop_all(self, timeout: float = 5.0) -> None:
        """SIGTERM everything, newest first; SIGKILL what has not exited after ``timeout``.
        Nothing can be restarted after this."""
        with self._lock:
            self._stopped = True
        for proc in reversed(list(self.procs.values())):
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + timeout
        for proc in self.procs.values():
            try:
                proc.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        for log in self._logs.values():
            log.close()
        self._logs.clear()
