"""The chaos bench's pure parts: the fault schedule, what the rogue sends, and how a run's
events, report and output are read into its row and the rows summed up."""

from __future__ import annotations

import signal

import numpy as np
import pytest

from fleet.bench import chaos
from fleet.bench.chaos import (
    FIRST,
    KINDS,
    LAST,
    NOTICED_WITHIN_S,
    Fault,
    aggregate,
    crashed,
    every_key,
    fault_outcome,
    fuzz_payloads,
    implausible_messages,
    make_fault,
    run_outcome,
    schedule,
    tasks_lost,
)
from fleet.params import load_fleet_config
from fleet.protocol import DecodeError, Keys, Message, decode, key_class
from fleet.rundir import RunDirError

CFG = load_fleet_config()


def test_the_schedule_is_seeded_sorted_within_the_job_and_names_its_targets() -> None:
    a = schedule(np.random.default_rng([0, 1]), 40, 100.0, 3)
    assert a == schedule(np.random.default_rng([0, 1]), 40, 100.0, 3)
    assert a != schedule(np.random.default_rng([0, 2]), 40, 100.0, 3)
    assert [f.at_s for f in a] == sorted(f.at_s for f in a)
    assert all(FIRST * 100 <= f.at_s <= LAST * 100 for f in a)
    assert {f.kind for f in a} == set(KINDS)
    for f in a:
        want = {
            "kill-agent": {"robot-0", "robot-1", "robot-2"},
            "stop-agent": {"robot-0", "robot-1", "robot-2"},
            "kill-coordinator": {"coordinator"},
            "rogue": {"rogue"},
        }[f.kind]
        assert f.target in want
    assert schedule(np.random.default_rng(0), 0, 100.0, 3) == []


def _message_classes() -> list[type[Message]]:
    import fleet.protocol as p

    return [
        c
        for c in vars(p).values()
        if isinstance(c, type) and issubclass(c, Message) and c is not Message
    ]


def test_no_fuzzed_payload_decodes_as_any_message() -> None:
    rng = np.random.default_rng(3)
    classes = _message_classes()
    assert len(classes) > 15
    for _key, kind in every_key(Keys("t"), ["robot-0"]):
        for payload in fuzz_payloads(rng, kind):
            for cls in classes:
                with pytest.raises(DecodeError):
                    decode(payload, cls)


def test_the_rogue_covers_every_key_class_and_its_messages_are_well_formed() -> None:
    keys = Keys("t")
    robots = ["robot-0", "robot-1"]
    classes = {key_class(k) for k, _ in every_key(keys, robots)}
    for topic in ("scan", "odom", "cmd_vel", "pose", "intent", "status", "heartbeat", "map"):
        assert f"robot/*/{topic}" in classes
    for cls in ("sim/clock", "coord/plan/*", "coord/award/*", "coord/bids/*", "coord/call"):
        assert cls in classes
    msgs = implausible_messages(keys, robots, 50.0, CFG, np.random.default_rng(0))
    for key, msg in msgs:
        again = decode(msg.encode(), type(msg))  # well-formed: only their values are wrong
        assert again.stamp == msg.stamp, key
    sent = {key_class(k) for k, _ in msgs}
    assert {"sim/clock", "robot/*/odom", "robot/*/scan", "robot/*/cmd_vel"} <= sent
    assert {"robot/*/pose", "robot/*/intent", "robot/*/status", "coord/bids/*"} <= sent


EVENTS = [
    {"seq": 1, "wall": 100.0, "kind": "auction", "robot": "", "task": ""},
    {"seq": 2, "wall": 101.2, "kind": "lost", "robot": "robot-1", "task": ""},
    {"seq": 3, "wall": 101.2, "kind": "reopened", "robot": "robot-1", "task": "t03"},
    {"seq": 4, "wall": 101.2, "kind": "reopened", "robot": "robot-1", "task": "t04"},
    {"seq": 5, "wall": 101.5, "kind": "reassigned", "robot": "robot-0", "task": "t03"},
    {"seq": 6, "wall": 101.9, "kind": "reassigned", "robot": "robot-2", "task": "t04"},
    {"seq": 7, "wall": 104.0, "kind": "rejoined", "robot": "robot-1", "task": ""},
    {"seq": 8, "wall": 110.0, "kind": "resumed", "robot": "", "task": ""},
]


def test_a_faults_detection_reassignment_and_the_coordinators_resumption() -> None:
    made = {"at_s": 30.0, "kind": "kill-agent", "target": "robot-1", "seq": 1, "sent": 100.5}
    out = fault_outcome(EVENTS, made)
    assert out["detection_s"] == pytest.approx(0.7)
    assert out["reassignment_s"] == pytest.approx(0.7)
    assert out["all_reassigned"] and out["rejoined"]
    coord = {"at_s": 40.0, "kind": "kill-coordinator", "target": "coordinator", "seq": 7}
    assert fault_outcome(EVENTS, {**coord, "sent": 108.0})["resumed_s"] == pytest.approx(2.0)
    # a loss never detected has no times; only the half re-sold is not all re-sold
    unseen = fault_outcome(EVENTS, {**made, "seq": 8})
    assert unseen["detection_s"] is None and unseen["reassignment_s"] is None
    # a loss long after the fault (the robot's token going at the run's end) is not its own
    late = fault_outcome(EVENTS, {**made, "sent": 101.2 - NOTICED_WITHIN_S - 1.0})
    assert late["detection_s"] is None
    half = fault_outcome(EVENTS[:5], made)
    assert half["reassignment_s"] == pytest.approx(0.3) and not half["all_reassigned"]


class _StoppedFleet:
    """A run whose fleet stops while its target is SIGSTOPped (its coordinator died): the
    SIGCONT finds the target gone."""

    def __init__(self) -> None:
        self.sent: list[tuple[str, int]] = []

    def events(self) -> list[dict]:
        return []

    def signal(self, name: str, sig: int) -> float:
        if sig == signal.SIGCONT:
            raise RunDirError(f"{name} (pid 4) is gone")
        self.sent.append((name, sig))
        return 0.0


def test_a_target_gone_before_its_fault_ends_is_noted_and_the_bench_goes_on(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The bench died when a SIGCONT found its target gone (the fleet stopped under it),
    before the run it was in was written; now the fault notes it and the run is recorded."""
    monkeypatch.setattr(chaos, "STOP_S", 0.0)
    fleet = _StoppedFleet()
    fault = Fault(20.0, "stop-agent", "robot-1")
    made = make_fault(fleet, fault, lambda: None)  # type: ignore[arg-type]
    assert fleet.sent == [("robot-1", signal.SIGSTOP)]
    assert made["error"] == "robot-1 (pid 4) is gone"
    assert fault_outcome([], {**made, "sent": 0.0})["error"] == made["error"]


def test_tasks_lost_are_those_neither_done_nor_left_out() -> None:
    report = {
        "tasks": [
            {"id": "t00", "state": "done"},
            {"id": "t01", "state": "replaced"},
            {"id": "t01.1", "state": "assigned"},
            {"id": "t02", "state": "blocked"},
            {"id": "t03", "state": "open"},
        ],
        "left_out": [{"id": "t02"}],
    }
    assert tasks_lost(report) == ["t01.1", "t03"]


def test_only_exits_the_bench_did_not_cause_are_crashes() -> None:
    output = (
        "robot-1 exited with code -9; `fleet respawn robot-1` starts it again\n"
        "coordinator exited with\ncode -9; ...\n"
        "robot-2 exited with code 1; `fleet respawn robot-2` starts it again\n"
        "robot-1 exited with code -9; again\n"
    )
    assert crashed(output, ["robot-1", "coordinator"]) == ["robot-2 (1)", "robot-1 (-9)"]
    assert crashed("", []) == []


def test_rows_and_their_summary() -> None:
    made = [
        {"at_s": 30.0, "kind": "kill-agent", "target": "robot-1", "seq": 1, "sent": 100.5},
        {**Fault(90.0, "stop-agent", "robot-0").__dict__, "fired": False},
    ]
    report = {
        "status": "done",
        "coverage": 0.96,
        "makespan_s": 140.0,
        "tasks": [{"id": "t00", "state": "done"}],
        "left_out": [],
    }
    row = run_outcome(report, made, EVENTS, "robot-1 exited with code -9", 130.0)
    assert row["finished"] and row["makespan_ratio"] == pytest.approx(1.077)
    assert row["tasks_lost"] == [] and row["crashed"] == []
    assert [f["fired"] for f in row["faults"]] == [True, False]
    failed = run_outcome(None, [], [], "", 130.0)
    assert not failed["finished"] and failed["tasks_lost"] is None
    s = aggregate([row, failed])
    assert (s["runs"], s["finished"], s["coverage_min"], s["faults_made"]) == (2, 1, 0.96, 1)
    kill = s["per_kind"]["kill-agent"]
    assert kill["made"] == 1 and kill["detection_s"]["median"] == pytest.approx(0.7)
    assert kill["makespan_ratio_mean"] == pytest.approx(1.077)
    assert s["per_kind"]["stop-agent"]["made"] == 0
