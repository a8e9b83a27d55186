"""One fleet at a time in a whole test run, whatever pytest and pytest-xdist schedule: a pytest
plugin (loaded by ``tests/conftest.py``) that holds an exclusive ``flock`` on ``fleet.lock``,
in the directory every process of the run shares, while a test marked ``integration`` runs
(its setup, its call and its teardown, module fixtures included), and writes down what ran
while it held it.

The shared directory is the run's base temp directory: with ``-n 0`` the one process's
``tmp_path_factory.getbasetemp()``; under xdist each worker's base temp is a directory in the
controller's, so a worker uses its base temp's parent (the sharing xdist's documentation
gives). The lock is taken before pytest-timeout starts a test's timer (a wait for another
worker's fleet is no part of the test's time), and kept while the next test this process runs
is in the same module (a module fixture may keep a process of it between its tests), so the
tests of that module that follow run under it too. It is given up after the last of them
however that one ended (passed, failed, errored, interrupted: the ``finally`` of the hook
wrapper), and with the process: the kernel drops a ``flock`` when the last descriptor of its
file closes, so a worker killed mid-fleet leaves it free.

``fleet-lock.jsonl`` beside the lock gets a line per test run under the lock (its node id,
pid, xdist worker, wall-clock start and end, seconds it waited for the lock, whether it is
marked ``integration``), written while the lock is held; the terminal summary says how many
tests held it, on how many processes, and whether any two overlapped."""

from __future__ import annotations

import fcntl
import json
import os
import time
from pathlib import Path

import pytest

LOCK_FILE = "fleet.lock"
RECORDS_FILE = "fleet-lock.jsonl"
MARK = "integration"


class FleetLock:
    """An exclusive ``flock`` on ``directory/fleet.lock``, blocking until it is free, and the
    record of the tests run while it is held (``directory/fleet-lock.jsonl``)."""

    def __init__(self, directory: Path) -> None:
        self.path = directory / LOCK_FILE
        self.records = directory / RECORDS_FILE
        self._fd: int | None = None
        self.waited = 0.0  # seconds the last acquire waited, until a record takes it

    @property
    def held(self) -> bool:
        return self._fd is not None

    def acquire(self) -> None:
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o600)
        asked = time.monotonic()
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except BaseException:
            os.close(fd)
            raise
        self.waited = time.monotonic() - asked
        self._fd = fd

    def release(self) -> None:
        fd, self._fd = self._fd, None
        if fd is not None:
            try:
                fcntl.flock(fd, fcntl.LOCK_UN)  # also for a forked child that shares the fd
            finally:
                os.close(fd)

    def record(self, test: str, start: float, end: float, fleet: bool) -> None:
        line = {
            "test": test,
            "pid": os.getpid(),
            "worker": os.environ.get("PYTEST_XDIST_WORKER", ""),
            "start": start,
            "end": end,
            "waited": round(self.waited, 3),
            "fleet": fleet,
        }
        self.waited = 0.0
        with self.records.open("a") as out:
            out.write(json.dumps(line) + "\n")


def read_records(path: Path) -> list[dict]:
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line]


def overlaps(records: list[dict]) -> list[tuple[dict, dict]]:
    """Every two records whose [start, end] overlap."""
    ordered = sorted(records, key=lambda r: r["start"])
    return [
        (a, b) for i, a in enumerate(ordered) for b in ordered[i + 1 :] if b["start"] < a["end"]
    ]


def shared_dir(config: pytest.Config) -> Path:
    """The directory all processes of this run share (see the module's docstring)."""
    # what the tmp_path_factory fixture returns; a hook has no fixtures
    base = config._tmp_path_factory.getbasetemp()
    return base.parent if hasattr(config, "workerinput") else base


_LOCK = pytest.StashKey[FleetLock]()


def _lock(config: pytest.Config) -> FleetLock:
    if _LOCK not in config.stash:
        config.stash[_LOCK] = FleetLock(shared_dir(config))
    return config.stash[_LOCK]


@pytest.hookimpl(wrapper=True, tryfirst=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):
    lock = _lock(item.config)
    fleet = item.get_closest_marker(MARK) is not None
    if fleet and not lock.held:
        lock.acquire()
    start = time.time()
    try:
        return (yield)
    finally:
        if lock.held:
            lock.record(item.nodeid, start, time.time(), fleet)
            if nextitem is None or nextitem.path != item.path:
                lock.release()


def pytest_terminal_summary(terminalreporter, config: pytest.Config) -> None:
    if hasattr(config, "workerinput"):
        return
    records = read_records(shared_dir(config) / RECORDS_FILE)
    if not records:
        return
    fleets = sum(r["fleet"] for r in records)
    pids = len({r["pid"] for r in records})
    waited = sum(r["waited"] for r in records)
    clashes = overlaps(records)
    said = "none" if not clashes else f"{len(clashes)} OVERLAPPING pairs"
    terminalreporter.write_line(
        f"fleet lock: {fleets} integration tests ({len(records)} in all) held it, on {pids} "
        f"process(es), {waited:.1f} s waiting for it; overlaps: {said}"
    )
    for a, b in clashes:
        terminalreporter.write_line(
            f"  {a['test']} (pid {a['pid']}) and {b['test']} (pid {b['pid']})"
        )
