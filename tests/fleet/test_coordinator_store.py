"""A coordinator state file is resumed only if it is whole and this fleet's: real files cut
short, overwritten, emptied, of another program or of another fleet are refused, naming the
file and why, and never resumed silently or replaced by a fresh start."""

from __future__ import annotations

import os
import sqlite3
from pathlib import Path

import numpy as np
import pytest
from robots import ROBOT

from fleet.coordinator.job import Job, TaskRecord
from fleet.coordinator.store import JobStore, StoreError
from planners.auction import Task
from planners.coverage.params import CoverageParams

OURS = {"fleet": "lab", "world": "home", "robots": 3}


def _job_file(path: Path, **identity: object) -> bytes:
    """A closed state file holding a job big enough to span many pages; its bytes."""
    store = JobStore(path, **identity)  # type: ignore[arg-type]
    rng = np.random.default_rng(0)
    tasks = [
        TaskRecord(Task(f"t{i:03d}", rng.random((100, 2)), 1.0, 2.0, tuple(range(40))))
        for i in range(200)
    ]
    store.save_tasks(tasks)
    for i in range(100):
        store.add_event(float(i), float(i), "awarded", "robot-0", f"t{i:03d}", "x" * 80)
    store.set_meta(phase="cleaning", expected_robots=3)
    store.close()
    return path.read_bytes()


def _refused(path: Path, match: str, **identity: object) -> str:
    before = path.read_bytes() if path.exists() else None
    with pytest.raises(StoreError, match=match) as e:
        JobStore(path, **identity)  # type: ignore[arg-type]
    message = str(e.value)
    assert str(path) in message
    # refused without a change: no fresh job written over it
    assert (path.read_bytes() if path.exists() else None) == before
    return message


def test_the_fleets_own_file_is_resumed(tmp_path: Path) -> None:
    path = tmp_path / "coordinator.sqlite"
    _job_file(path, **OURS)
    store = JobStore(path, **OURS)  # type: ignore[arg-type]
    job = Job(CoverageParams(), ROBOT, 0.0)
    store.load_job(job)
    assert len(job.tasks) == 200
    meta = store.meta()
    assert (meta["fleet"], meta["world"], meta["expected_robots"]) == ("lab", "home", 3)
    store.close()


def test_a_task_of_a_kind_this_version_does_not_have_is_refused_naming_the_file(
    tmp_path: Path,
) -> None:
    """A job saved by a version with another task kind (``freed``, the floor furniture taken
    away freed, swept by a task of its own until that option went) is not resumed: the store
    says which file and why, as it does for every file it cannot resume."""
    path = tmp_path / "coordinator.sqlite"
    _job_file(path, **OURS)
    db = sqlite3.connect(path)
    db.execute("UPDATE tasks SET kind = 'freed' WHERE id = 't007'")
    db.commit()
    db.close()
    store = JobStore(path, **OURS)  # type: ignore[arg-type]
    with pytest.raises(StoreError, match="t007: kind 'freed' is not one of") as e:
        store.load_job(Job(CoverageParams(), ROBOT, 0.0))
    store.close()
    assert str(path) in str(e.value)


@pytest.mark.parametrize("share", [0.9, 0.5, 0.02])
def test_a_file_cut_short_is_refused(tmp_path: Path, share: float) -> None:
    path = tmp_path / "coordinator.sqlite"
    data = _job_file(path, **OURS)
    path.write_bytes(data[: int(len(data) * share)])
    message = _refused(path, r"cut short", **OURS)
    assert f"{int(len(data) * share)} bytes of the {len(data)}" in message


def test_a_file_cut_to_less_than_a_header_or_to_nothing_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "coordinator.sqlite"
    data = _job_file(path, **OURS)
    path.write_bytes(data[:50])
    _refused(path, r"cut short: 50 bytes, less than an SQLite header", **OURS)
    path.write_bytes(b"")
    _refused(path, r"empty \(0 bytes\)", **OURS)


def test_a_damaged_file_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "coordinator.sqlite"
    data = bytearray(_job_file(path, **OURS))
    middle = len(data) // 2
    data[middle : middle + 8192] = os.urandom(8192)
    path.write_bytes(bytes(data))
    _refused(path, r"damaged \(", **OURS)


def test_a_file_that_is_not_sqlite_or_not_a_state_file_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "coordinator.sqlite"
    path.write_text("phase: cleaning\n" * 100)
    _refused(path, r"not an SQLite database \(it begins b'phase: cleaning", **OURS)
    other = tmp_path / "other.sqlite"
    db = sqlite3.connect(other)
    db.executescript("CREATE TABLE songs (title TEXT); INSERT INTO songs VALUES ('x');")
    db.commit()
    db.close()
    _refused(other, r"not a job state file of the coordinator \(its tables: songs\)", **OURS)


@pytest.mark.parametrize(
    ("field", "value", "said"),
    [
        ("fleet", "kitchen", "fleet 'kitchen'"),
        ("world", "small", "world 'small'"),
        ("robots", 2, "2 robots"),
    ],
)
def test_a_file_of_another_fleet_is_refused(
    tmp_path: Path, field: str, value: object, said: str
) -> None:
    path = tmp_path / "coordinator.sqlite"
    _job_file(path, **OURS)
    message = _refused(
        path,
        "the job of fleet 'lab', world 'home', 3 robots",
        **{
            **OURS,
            field: value,
        },
    )
    assert f"not of {said}" in message.replace("fleet 'lab', ", "").replace("world 'home', ", "")


def test_a_new_file_is_started_and_records_its_fleet(tmp_path: Path) -> None:
    path = tmp_path / "run" / "coordinator.sqlite"
    store = JobStore(path, **OURS)  # type: ignore[arg-type]
    assert store.meta()["fleet"] == "lab" and store.meta()["expected_robots"] == 3
    store.close()
