"""RunRecorder: what `fleet up` records for the report goes to the run dir as it comes, and
reads back as it was heard."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from fleet.protocol import (
    TIME_KINDS,
    Clock,
    Collision,
    CoverageImage,
    CoverageSummary,
    Keys,
    Plan,
    RobotStatus,
    TruthPose,
)
from fleet.report.repetition import read_plans, read_status
from fleet.report.summary import (
    COLLISION_COLUMNS,
    COLLISIONS_FILE,
    COVERAGE_COLUMNS,
    COVERAGE_FILE,
    GRID_FILE,
    PLANS_FILE,
    STATUS_FILE,
    TRACK_STEP_M,
    TRACKS_FILE,
    RunRecorder,
    read_csv,
    read_tracks,
)

TOUR = np.array([[0.2, 0.3], [1.8, 0.3], [1.8, 0.6]])
TIMES = np.arange(len(TIME_KINDS), dtype=float)


class _Bus:
    """What RunRecorder needs of a bus: its keys, and subscriptions it can be fed through."""

    def __init__(self) -> None:
        self.keys = Keys("test")
        self.handlers: dict[str, Callable] = {}
        self.dropped: list[tuple[str, str, str]] = []

    def subscribe(self, key: str, _type: type, handler: Callable) -> None:
        self.handlers[key] = handler

    def watch_alive(self, _role: str, on_join: Callable, _on_leave: Callable) -> None:
        self.handlers["alive"] = on_join

    def drop_implausible(self, key: str, sender: str, why: str, n: int = 1) -> None:
        self.dropped.append((key, sender, why))


def _recorder(
    run_dir: Path, clock: tuple[float, ...] = (0.4, 0.8, 1.2)
) -> tuple[_Bus, RunRecorder]:
    bus = _Bus()
    recorder = RunRecorder(bus, 0.5, run_dir)  # type: ignore[arg-type]
    for t in clock:
        bus.handlers[bus.keys.clock()](bus.keys.clock(), Clock(t, 1.0))
    return bus, recorder


def _status(t: float, plan_id: int = 7) -> RobotStatus:
    return RobotStatus(t, "driving", "t00", 0.5, 3, 6, 1.0, plan_id=plan_id, time_s=t * TIMES)


def _summary(t: float, coverage: float) -> CoverageSummary:
    none = np.zeros(0)
    return CoverageSummary(t, 1.0, coverage, 0.1, 10.0, [], none, none, none, none)


def _image() -> CoverageImage:
    return CoverageImage(
        2.0, 0.05, 0.0, 0.0, 20, 40, np.zeros(800, np.uint16), np.ones(800, np.uint8)
    )


def test_the_recorder_round_trips_and_what_it_heard_is_on_disk_before_the_end(tmp_path: Path):
    """Every kind of record reads back as it was heard, track points thinned to TRACK_STEP_M,
    and each is in its file as soon as it was heard: a `fleet up` that dies mid-run leaves it."""
    bus, recorder = _recorder(tmp_path)
    keys = bus.keys
    bus.handlers["alive"]("robot-0")
    bus.handlers["alive"]("robot-1")
    on_truth = bus.handlers[keys.all_robots("truth")]
    steps = [0.0, 0.005, 0.02, 0.04, 0.06]  # the 5 mm step is under the track step
    for k, dx in enumerate(steps):
        for i, rid in enumerate(("robot-0", "robot-1")):
            pose = TruthPose(1.0 + 0.1 * k, 0.5 + dx, 1.0 + i, 0.0)
            on_truth(keys.robot(rid, "truth"), pose)
    for t, cov in ((1.0, 0.1), (1.5, 0.2), (1.5, 0.3)):  # a repeated stamp is heard once
        bus.handlers[keys.coverage()](keys.coverage(), _summary(t, cov))
    contact = Collision(1.1, "wall", "robot-0", "", 0.51, 1.0)
    bus.handlers[keys.collisions()](keys.collisions(), contact)
    for rid, t in (("robot-1", 1.5), ("robot-1", 1.0), ("robot-0", 1.2)):
        bus.handlers[keys.all_robots("status")](keys.robot(rid, "status"), _status(t))
    plan = Plan(1.0, 7, "t00", TOUR, 0, ["t00"], np.array([0], dtype=np.int32))
    bus.handlers[keys.plan("*")](keys.plan("robot-1"), plan)

    def check() -> None:
        tracks = read_tracks(tmp_path / TRACKS_FILE)
        kept = [0.5, 0.52, 0.54, 0.56]
        assert sorted(tracks) == ["robot-0", "robot-1"]
        for i, rid in enumerate(("robot-0", "robot-1")):
            assert np.allclose(tracks[rid][:, 1], kept) and np.allclose(tracks[rid][:, 2], 1.0 + i)
            assert np.all(np.abs(np.diff(tracks[rid][:, 1])) >= TRACK_STEP_M - 1e-9)
        coverage = [row for _, row in read_csv(tmp_path / COVERAGE_FILE, COVERAGE_COLUMNS)]
        assert [(r["sim_s"], r["coverage"]) for r in coverage] == [("1.0", "0.1"), ("1.5", "0.2")]
        collisions = [row for _, row in read_csv(tmp_path / COLLISIONS_FILE, COLLISION_COLUMNS)]
        assert [(r["kind"], r["robot"], r["x"]) for r in collisions] == [
            ("wall", "robot-0", "0.51")
        ]
        status = read_status(tmp_path / STATUS_FILE, {})
        assert status["robot-1"][:, 0].tolist() == [1.0, 1.5]
        assert np.allclose(status["robot-1"][1, 3:], 1.5 * TIMES)
        assert status["robot-0"][:, 1:3].tolist() == [[7, 3]]
        plans = read_plans(tmp_path / PLANS_FILE, {})
        assert np.array_equal(plans["robot-1", 7]["waypoints"], TOUR)

    check()  # mid-run: nothing closed, nothing written at the end yet
    recorder.finish(_image(), 0.3)
    check()
    assert (tmp_path / GRID_FILE).exists()
    # after the end, late messages change nothing
    bus.handlers[keys.all_robots("status")](keys.robot("robot-0", "status"), _status(2.0))
    assert read_status(tmp_path / STATUS_FILE, {})["robot-0"][:, 0].tolist() == [1.2]


def test_the_recorder_drops_what_is_stamped_past_the_sim_clock(tmp_path: Path) -> None:
    """A status or a coverage summary stamped far ahead would stand as the newest and hide the
    real ones after it; the recorder drops it, counted, once it knows the sim clock."""
    # a receiver started late believes the clock once confirmed
    bus, recorder = _recorder(tmp_path, (9.9, 10.0, 10.1))
    keys = bus.keys
    bus.handlers["alive"]("robot-1")
    for t in (1e9, 10.2):
        bus.handlers[keys.all_robots("status")](keys.robot("robot-1", "status"), _status(t))
    for t in (1e9, 10.3):
        bus.handlers[keys.coverage()](keys.coverage(), _summary(t, 1.0))
    recorder.close()
    assert read_status(tmp_path / STATUS_FILE, {})["robot-1"][:, 0].tolist() == [10.2]
    coverage = read_csv(tmp_path / COVERAGE_FILE, COVERAGE_COLUMNS)
    assert [row["sim_s"] for _, row in coverage] == ["10.3"]
    assert [(k, who) for k, who, _ in bus.dropped] == [
        (keys.robot("robot-1", "status"), "robot-1"),
        (keys.coverage(), "sim"),
    ]


def test_the_recorder_drops_the_statuses_of_a_robot_not_in_the_job(tmp_path: Path) -> None:
    """A status from a robot whose liveliness token was never heard is no robot of the run's:
    the recorder drops it, counted with its sender named, and keeps those of robots in the job.
    """
    bus, recorder = _recorder(tmp_path, (0.5,))
    keys = bus.keys
    bus.handlers["alive"]("robot-0")
    for rid in ("ghost", "robot-0"):
        bus.handlers[keys.all_robots("status")](keys.robot(rid, "status"), _status(1.0))
    assert list(read_status(tmp_path / STATUS_FILE, {})) == ["robot-0"]
    # counted once the ghost's token has not come within the grace
    assert bus.dropped == []
    recorder.watch.strangers.grace_s = 0.0
    recorder.watch.strangers.flush()
    assert [(k, who) for k, who, _ in bus.dropped] == [(keys.robot("ghost", "status"), "ghost")]
    recorder.close()
