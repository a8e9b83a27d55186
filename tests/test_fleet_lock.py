"""The fleet lock (tests/fleet_lock.py): a real pytest run on two xdist workers, each given an
``integration`` test that holds on for a moment, runs them one after the other (by the
intervals the lock writes down), a failing one giving the lock up; and a process killed while
it holds the lock leaves it free."""

from __future__ import annotations

import fcntl
import os
import subprocess
import sys
from pathlib import Path

import pytest
from fleet_lock import LOCK_FILE, RECORDS_FILE, FleetLock, overlaps, read_records

TESTS = Path(__file__).resolve().parent
HOLD_S = 1.5

PROBE = f"""
import time

import pytest

pytestmark = pytest.mark.integration


def test_a_fleet_that_fails():
    time.sleep({HOLD_S})
    raise AssertionError("a failed fleet test gives the lock up all the same")


def test_a_fleet_that_passes():
    time.sleep({HOLD_S})
"""


def _env() -> dict[str, str]:
    """This environment without the outer run's xdist worker variables, ``tests/`` importable."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(TESTS), env.get("PYTHONPATH")) if p)
    return env


@pytest.mark.timeout(120)
def test_two_workers_run_their_fleet_tests_one_after_the_other(tmp_path: Path) -> None:
    (tmp_path / "test_probe.py").write_text(PROBE)
    (tmp_path / "pytest.ini").write_text("[pytest]\nmarkers =\n    integration: a fleet\n")
    base = tmp_path / "base"
    # --dist load with two tests and two workers: one test to each, free to run at once
    argv = ["-p", "fleet_lock", "-n", "2", "--dist", "load", "-p", "no:cacheprovider"]
    done = subprocess.run(
        [sys.executable, "-m", "pytest", *argv, "--basetemp", str(base), "test_probe.py"],
        cwd=tmp_path,
        env=_env(),
        capture_output=True,
        text=True,
        timeout=100,
    )
    out = done.stdout + done.stderr
    assert "1 failed, 1 passed" in out, out
    records = read_records(base / RECORDS_FILE)
    assert sorted(r["test"].rsplit("::", 1)[1] for r in records) == [
        "test_a_fleet_that_fails",
        "test_a_fleet_that_passes",
    ], out
    assert len({r["pid"] for r in records}) == 2, records  # on both workers
    first, second = sorted(records, key=lambda r: r["start"])
    assert first["end"] - first["start"] >= HOLD_S
    assert second["start"] >= first["end"], f"two fleet tests overlapped: {records}"
    assert second["waited"] > 0.5, records  # it was held up by the first
    assert overlaps(records) == []
    assert "fleet lock: 2 integration tests (2 in all) held it, on 2 process(es)" in out, out
    assert "overlaps: none" in out, out


HOLDER = """
import sys, time
from pathlib import Path
from fleet_lock import FleetLock

FleetLock(Path(sys.argv[1])).acquire()
print("held", flush=True)
time.sleep(60)
"""


def _free(directory: Path) -> bool:
    fd = os.open(directory / LOCK_FILE, os.O_RDWR)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    finally:
        os.close(fd)
    return True


@pytest.mark.timeout(30)
def test_a_holder_killed_mid_test_leaves_the_lock_free(tmp_path: Path) -> None:
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(tmp_path)],
        stdout=subprocess.PIPE,
        text=True,
        env=_env(),
    )
    try:
        assert holder.stdout.readline() == "held\n"
        assert not _free(tmp_path)
    finally:
        holder.kill()
        holder.wait()
    assert _free(tmp_path)
    lock = FleetLock(tmp_path)
    lock.acquire()
    assert lock.held and not _free(tmp_path)
    lock.release()
    assert not lock.held and _free(tmp_path)


def test_overlaps_are_found_between_any_two_records() -> None:
    def r(name: str, start: float, end: float) -> dict:
        return {"test": name, "start": start, "end": end}

    apart = [r("a", 0, 1), r("b", 1, 2), r("c", 5, 9)]
    assert overlaps(apart) == []
    inside = [*apart, r("d", 6, 7)]
    assert [(a["test"], b["test"]) for a, b in overlaps(inside)] == [("c", "d")]
    across = [r("a", 0, 10), r("b", 2, 3), r("c", 4, 5)]
    assert len(overlaps(across)) == 2
