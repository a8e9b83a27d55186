"""fleet up's waits on other processes survive a starved machine: a process is waited for
again while it works (alive and using CPU), and given up on once it is dead, stopped or hung."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

from fleet.protocol import CoverageSummary, Request
from fleet.supervisor import fleet_processes
from fleet.supervisor.launcher import WorkWatch, cpu_ticks

BUSY = "while True: pass"
IDLE = "import time; time.sleep(60)"


def _start(code: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", code])


def _settle(watch: WorkWatch, seconds: float = 0.5) -> bool:
    watch.working()
    time.sleep(seconds)
    return watch.working()


def test_a_busy_process_works_an_idle_stopped_or_dead_one_does_not() -> None:
    busy, idle = _start(BUSY), _start(IDLE)
    try:
        time.sleep(0.5)  # past the interpreter's start, which uses CPU
        b, i = WorkWatch(busy), WorkWatch(idle)
        assert _settle(b) and not _settle(i)
        busy.send_signal(signal.SIGSTOP)
        time.sleep(0.1)
        assert not _settle(b)
        busy.send_signal(signal.SIGCONT)
        assert _settle(b)
        busy.kill()
        busy.wait()
        assert not b.working() and cpu_ticks(busy.pid) is None
    finally:
        for p in (busy, idle):
            p.kill()
            p.wait()


class _SlowBus:
    """A bus whose query finds no simulator to answer ``misses`` times (and returns at once, as
    a query nothing serves does) before the answer comes."""

    def __init__(self, misses: int) -> None:
        self.misses = misses
        self.asked = 0

    def request(self, key: str, msg: Request, cls: type, timeout: float) -> object:
        self.asked += 1
        if self.asked <= self.misses:
            raise TimeoutError(f"{key}: no valid reply after 0.0 s (timeout {timeout} s)")
        return "the report"


class _Sim:
    def __init__(self, alive: bool = True, works: bool = True) -> None:
        self.is_alive = alive
        self.works = works

    def alive(self) -> bool:
        return self.is_alive

    def working(self) -> bool:
        return self.works


@pytest.fixture
def quick(monkeypatch: pytest.MonkeyPatch) -> None:
    """The report's waits shorter: the poll and each judgement a hundred times, the give-up
    window ten times, so that twenty misses on a loaded machine (sleeps overshooting) still
    fall well inside it (0.3 s failed once in a CI run with a bench beside it)."""
    monkeypatch.setattr(fleet_processes, "REPORT_POLL_S", 0.01)
    monkeypatch.setattr(fleet_processes, "REPORT_WAIT_S", 0.05)
    monkeypatch.setattr(fleet_processes, "REPORT_GIVE_UP_S", 3.0)


def test_a_simulator_not_serving_yet_is_asked_again_until_it_answers(quick: None) -> None:
    bus = _SlowBus(misses=20)
    t0 = time.monotonic()
    answer = fleet_processes.ask_sim(bus, "sim/report", CoverageSummary, _Sim())  # type: ignore[arg-type]
    assert answer == "the report" and bus.asked == 21
    # a query nothing serves returns at once: it is not asked again sooner than the poll
    assert time.monotonic() - t0 >= 20 * fleet_processes.REPORT_POLL_S


def test_a_simulator_that_exited_or_does_not_work_is_given_up(quick: None) -> None:
    with pytest.raises(TimeoutError, match="has exited"):
        fleet_processes.ask_sim(_SlowBus(5), "sim/report", CoverageSummary, _Sim(alive=False))  # type: ignore[arg-type]
    bus = _SlowBus(1000)
    with pytest.raises(TimeoutError, match="not working"):
        fleet_processes.ask_sim(bus, "sim/report", CoverageSummary, _Sim(works=False))  # type: ignore[arg-type]
    # judged over a whole REPORT_WAIT_S, not at the first miss
    assert bus.asked > 1
    with pytest.raises(TimeoutError, match="still works but does not answer"):
        fleet_processes.ask_sim(_SlowBus(1000), "sim/report", CoverageSummary, _Sim())  # type: ignore[arg-type]
