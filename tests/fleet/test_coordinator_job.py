"""The job's rules without a bus: awards, swept pieces, losing a robot, rebalancing, and the
job on disk."""

from __future__ import annotations

import json

import numpy as np
import pytest
from robots import ROBOT

from fleet.coordinator.job import (
    ASSIGNED,
    BLOCKED,
    DONE,
    GONE,
    LOST,
    OPEN,
    REPLACED,
    STRANDED,
    UNREACHABLE,
    GivenUpWaypoints,
    Job,
)
from fleet.coordinator.store import STORE_VERSION, JobStore
from fleet.protocol import Plan
from fleet.supervisor.runner import read_events
from planners.auction import Task
from planners.coverage.params import CoverageParams


def _task(tid: str, x0: float, pieces: int = 4) -> Task:
    path = np.column_stack([x0 + np.arange(pieces + 1, dtype=float), np.zeros(pieces + 1)])
    return Task(tid, path, float(pieces), 2.0 * pieces, (1,))


@pytest.fixture
def job() -> Job:
    j = Job(CoverageParams(), ROBOT, 0.0)
    j.add_tasks(tuple(_task(f"t{i:02d}", 10.0 * i) for i in range(4)))
    for rid in ("robot-0", "robot-1"):
        r = j.robot(rid)
        r.ready, r.xy = True, (0.0, 0.0)
    return j


def test_awards_build_each_robots_queue_in_order(job: Job):
    job.award("t00", "robot-0", False)
    job.award("t02", "robot-0", True)
    job.award("t01", "robot-1", False)
    assert [r.task.id for r in job.queue("robot-0")] == ["t00", "t02"]
    assert job.current("robot-1").task.id == "t01"
    assert job.counts() == {OPEN: 1, ASSIGNED: 3, DONE: 0, BLOCKED: 0, UNREACHABLE: 0, STRANDED: 0}
    with pytest.raises(ValueError, match="not open"):
        job.award("t00", "robot-1", False)


def test_a_dropped_task_is_gone_from_its_owner_and_the_market(job: Job):
    job.award("t00", "robot-0", False)
    job.award("t01", "robot-0", False)
    assert job.drop("t00") == "robot-0"
    assert job.drop("t02") is None  # open: no owner
    assert job.drop("t02") is None and job.tasks["t02"].state == GONE  # already gone
    assert [r.task.id for r in job.queue("robot-0")] == ["t01"]
    assert job.tasks["t00"].owner is None and job.tasks["t00"].state == GONE
    assert [r.task.id for r in job.open_tasks()] == ["t03"]
    job.finish("robot-0", "t01")
    job.tasks["t03"].state = UNREACHABLE
    job.drop("t03")  # mapped another way: no work left out
    assert job.finished and not job.left_out()
    assert job.drop("t01") is None and job.tasks["t01"].state == DONE


def test_swept_pieces_of_a_reversed_task_map_back_to_its_own_order(job: Job):
    job.award("t00", "robot-0", True)
    # driven backwards: the first piece driven is the task's last
    assert job.progress("robot-0", "t00", np.array([1, 1, 0, 0], dtype=np.uint8))
    assert job.tasks["t00"].swept.tolist() == [False, False, True, True]
    assert not job.progress("robot-0", "t00", np.array([1, 0, 0, 0], dtype=np.uint8))
    # reports from a robot that does not hold the task, or of the wrong length, change nothing
    assert not job.progress("robot-1", "t00", np.ones(4, dtype=np.uint8))
    assert not job.progress("robot-0", "t00", np.ones(3, dtype=np.uint8))


def test_a_lost_robot_leaves_the_unswept_remainder_and_its_unstarted_tasks(job: Job):
    job.award("t00", "robot-0", False)
    job.award("t01", "robot-0", False)
    job.award("t02", "robot-1", False)
    job.progress("robot-0", "t00", np.array([1, 1, 0, 0], dtype=np.uint8))
    job.robots["robot-0"].xy = (2.5, 0.05)
    reopened, made = job.lose("robot-0")
    assert made == ["t00.1"]
    assert sorted(reopened) == ["t00.1", "t01"]
    assert job.tasks["t00"].state == REPLACED
    rest = job.tasks["t00.1"]
    assert rest.state == OPEN and rest.parent == "t00"
    # the rest begins two robot radii past where it stopped, mid-piece: its body is in the way
    gap = 2 * (job.spec.radius + job.wall_clearance)
    assert np.allclose(rest.task.path[0], [2.5 + gap, 0.0]) and np.allclose(
        rest.task.path[-1], [4, 0]
    )
    assert job.tasks["t01"].state == OPEN and job.tasks["t01"].owner is None
    assert job.robots["robot-0"].liveness == LOST
    assert job.queue("robot-0") == []
    assert job.market() == ["robot-1"]
    # the other robot's work is untouched, and no task is in two queues
    assert [r.task.id for r in job.queue("robot-1")] == ["t02"]
    # a second loss of the remainder's owner numbers the next remainder on
    job.award("t00.1", "robot-1", False)
    job.progress("robot-1", "t00.1", np.array([1, 0], dtype=np.uint8))
    job.robots["robot-1"].xy = None
    job.lose("robot-1")
    assert "t00.2" in job.tasks  # by pieces, without a pose


def test_a_robot_lost_before_sweeping_anything_gives_back_whole_tasks(job: Job):
    job.award("t00", "robot-0", True)
    reopened, made = job.lose("robot-0")
    assert reopened == ["t00"] and made == []
    assert job.tasks["t00"].state == OPEN and not job.tasks["t00"].reverse


def test_withdrawing_takes_back_the_far_half_of_the_unstarted_queued_tasks(job: Job):
    for tid in ("t00", "t01", "t02"):
        job.award(tid, "robot-0", False)
    job.award("t03", "robot-1", False)
    # robot-0 drives t00 and keeps the near half of the rest; robot-1 keeps what it drives
    assert job.withdraw_unstarted() == ["t02"]
    assert [r.task.id for r in job.queue("robot-0")] == ["t00", "t01"]
    assert [r.task.id for r in job.queue("robot-1")] == ["t03"]
    # a task already begun is never withdrawn; a single unstarted one is
    job.progress("robot-0", "t01", np.array([1, 0, 0, 0], dtype=np.uint8))
    assert job.withdraw_unstarted() == []
    job.award("t02", "robot-1", False)
    assert job.withdraw_unstarted() == ["t02"]


def test_the_job_is_finished_when_every_task_is_done_or_replaced(job: Job):
    for tid in ("t00", "t01", "t02", "t03"):
        job.award(tid, "robot-0", False)
    job.progress("robot-0", "t00", np.array([1, 0, 0, 0], dtype=np.uint8))
    job.lose("robot-0")
    robot = job.robots["robot-1"]
    for rec in job.open_tasks():
        job.award(rec.task.id, robot.id, False)
    for rec in job.queue(robot.id):
        assert not job.finished
        assert job.finish(robot.id, rec.task.id)
    assert job.finished
    assert not job.finish(robot.id, "t01")


def test_the_store_gives_back_the_job_and_the_plans(job: Job, tmp_path):
    job.award("t00", "robot-0", True)
    job.progress("robot-0", "t00", np.array([1, 0, 0, 0], dtype=np.uint8))
    job.award("t01", "robot-1", False)
    job.robots["robot-1"].award_seq = 3
    job.replace("t02", (np.array([[20.0, 0.0], [21.0, 0.0]]),), (), "robot-2")
    job.tasks["t02.1"].tried = frozenset({"robot-1"})
    job.replace("t03", (), [(np.array([[30.0, 0.0], [31.0, 0.0]]), 0.1)], "robot-2")
    store = JobStore(tmp_path / "job.sqlite")
    store.save_tasks(list(job.tasks.values()))
    store.save_robots(list(job.robots.values()))
    waypoints = np.array([[5.0, 0.0], [4.0, 0.0], [0.0, 0.0], [10.0, 0.0]])
    plan = Plan(12.5, 7, "t00", waypoints, 1, ["t00", "t01"], np.array([1, 2], dtype=np.int32))
    store.save_plan("robot-0", plan)
    store.set_meta(phase="cleaning", plan_seq=7)
    store.add_event(1.0, 2.0, "awarded", "robot-0", "t00", "")
    store.close()

    again = Job(CoverageParams(), ROBOT, 0.0)
    store = JobStore(tmp_path / "job.sqlite")
    store.load_job(again)
    assert set(again.tasks) == set(job.tasks)
    t00 = again.tasks["t00"]
    assert t00.owner == "robot-0" and t00.reverse and t00.state == ASSIGNED
    assert t00.swept.tolist() == job.tasks["t00"].swept.tolist()
    assert np.array_equal(t00.task.path, job.tasks["t00"].task.path)
    assert again.robots["robot-1"].award_seq == 3
    assert not again.robots["robot-1"].ready
    assert again.tasks["t02.1"].tried == {"robot-1"}
    assert again.tasks["t03.1"].state == BLOCKED and again.tasks["t03.1"].blocked_by == "robot-2"
    assert store.plans()["robot-0"] == plan
    assert store.meta() == {"phase": "cleaning", "plan_seq": 7, "store_version": STORE_VERSION}
    assert [e["kind"] for e in read_events(tmp_path / "job.sqlite")] == ["awarded"]
    store.close()


def test_a_state_file_of_another_layout_is_refused(tmp_path):
    import sqlite3

    from fleet.coordinator.store import StoreError

    path = tmp_path / "old.sqlite"
    db = sqlite3.connect(path)
    db.executescript(
        "CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT);"
        "CREATE TABLE tasks (id TEXT PRIMARY KEY, parent TEXT, area_m2 REAL, time_s REAL,"
        " path BLOB, cells TEXT, state TEXT, owner TEXT, position INTEGER, reverse INTEGER,"
        " swept BLOB, created_wall REAL, done_wall REAL);"
        "INSERT INTO tasks (id, state) VALUES ('t00', 'open');"
    )
    db.commit()
    db.close()
    with pytest.raises(StoreError, match=rf"old\.sqlite.*layout version none, not {STORE_VERSION}"):
        JobStore(path)


def test_the_report_rebuilds_owners_over_time_and_finds_a_task_held_twice(tmp_path):
    from fleet.report.summary import job_report

    job = Job(CoverageParams(), ROBOT, 0.0)
    job.add_tasks((_task("t00", 0.0), _task("t01", 10.0)))
    store = JobStore(tmp_path / "job.sqlite")
    store.save_tasks(list(job.tasks.values()))
    for sim, kind, robot, task in (
        (1.0, "awarded", "robot-0", "t00"),
        (1.0, "awarded", "robot-1", "t01"),
        (5.0, "lost", "robot-0", ""),
        (5.1, "reassigned", "robot-1", "t00"),
        (9.0, "done", "robot-1", "t01"),
        (9.5, "awarded", "robot-2", "t01"),
    ):
        store.add_event(0.0, sim, kind, robot, task, "")
    store.set_meta(
        rejected_bids={"late": 2},
        estimate_s=123.4,
        given_up_waypoints={"by_robot": {"robot-1": 2}, "seen": {"robot-1/3": 2}},
        tour={"coverage": 0.995, "repetition": 0.285},
    )
    store.close()
    report = job_report(tmp_path / "job.sqlite")
    assert report["plan_estimate_s"] == 123.4
    assert report["plan"] == {"coverage": 0.995, "repetition": 0.285}
    assert report["given_up_waypoints"] == {"robot-1": 2}
    owners = {t["id"]: t["owners"] for t in report["tasks"]}
    assert owners["t00"] == [["robot-0", 1.0, 5.0], ["robot-1", 5.1, None]]
    # t01 was done by robot-1 and then awarded again: held by one robot at a time
    assert owners["t01"] == [["robot-1", 1.0, 9.0], ["robot-2", 9.5, None]]
    assert report["overlaps"] == []
    assert report["rejected_bids"] == {"late": 2}
    assert [e["kind"] for e in report["events"]][:2] == ["awarded", "awarded"]

    store = JobStore(tmp_path / "job.sqlite")
    store.add_event(0.0, 9.6, "awarded", "robot-0", "t01", "")
    store.close()
    assert job_report(tmp_path / "job.sqlite")["overlaps"] == ["t01"]
    assert job_report(tmp_path / "missing.sqlite")["tasks"] is None
    assert job_report(tmp_path / "missing.sqlite")["plan_estimate_s"] is None
    assert job_report(tmp_path / "missing.sqlite")["plan"] is None


def test_given_up_waypoints_are_counted_across_plans_cuts_and_a_restart() -> None:
    given_up = GivenUpWaypoints()
    assert given_up.finished_message() == "every task is done, no waypoint given up"
    for plan_id, skipped in ((1, 0), (1, 1), (1, 1), (1, 2), (2, 0), (2, 1)):
        given_up.report("robot-0", plan_id, skipped)
    # a cut plan under the same id: the agent's count starts again and rises once more
    given_up.report("robot-0", 2, 0)
    given_up.report("robot-0", 2, 1)
    given_up.report("robot-1", 5, 2)
    assert given_up.by_robot == {"robot-0": 4, "robot-1": 2}
    # the coordinator restarts from its state file; the agents report their counts again
    resumed = GivenUpWaypoints.from_json(json.loads(json.dumps(given_up.to_json())))
    assert resumed.report("robot-1", 5, 2) == 0
    assert resumed.report("robot-1", 5, 3) == 1
    assert resumed.total == 7
    message = resumed.finished_message()
    assert "7 waypoint(s) were given up" in message and "robot-0 4, robot-1 3" in message
    assert "the floor is clean" not in message


def test_pieces_given_up_go_back_until_every_robot_has_tried_them(job: Job):
    job.award("t00", "robot-0", False)
    job.progress("robot-0", "t00", np.array([1, 1, 0, 0], dtype=np.uint8))
    again = job.give_back("robot-0", "t00")
    assert again == "t00.1"
    assert job.tasks["t00"].state == REPLACED and job.tasks["t00"].owner is None
    rest = job.tasks[again]
    assert rest.state == OPEN and rest.parent == "t00" and rest.task.pieces == 2
    assert rest.tried == {"robot-0"}
    assert job.settle_unreachable() == []  # robot-1 has not tried it
    # robot-1 leaves pieces of it unswept too: every robot in the market has tried it now
    job.award(again, "robot-1", False)
    job.progress("robot-1", again, np.array([1, 0], dtype=np.uint8))
    last = job.give_back("robot-1", again)
    assert last is not None and job.tasks[last].tried == {"robot-0", "robot-1"}
    assert job.give_back("robot-1", "t01") is None  # not its task
    assert job.settle_unreachable() == [last]
    assert job.tasks[last].state == UNREACHABLE
    # never counted done: the job finishes incomplete, with the piece named
    for tid in ("t01", "t02", "t03"):
        job.award(tid, "robot-0", False)
        job.finish("robot-0", tid)
    assert job.finished and job.incomplete
    assert [r.task.id for r in job.left_out()] == [last]
    # a robot that joins has not tried it: it opens again
    r = job.robot("robot-2")
    r.ready, r.xy = True, (0.0, 0.0)
    assert job.reopen() == [last] and job.tasks[last].state == OPEN
    assert not job.finished


def test_a_stuck_robot_gives_back_its_work(job: Job):
    job.award("t00", "robot-0", False)
    job.award("t01", "robot-0", False)
    job.progress("robot-0", "t00", np.array([1, 0, 0, 0], dtype=np.uint8))
    reopened = job.release("robot-0")
    assert reopened == ["t00.1", "t01"]
    assert job.queue("robot-0") == []
    assert job.tasks["t00.1"].tried == {"robot-0"} and job.tasks["t01"].tried == frozenset()
    assert job.robots["robot-0"].in_market  # alive: it may win other work


def test_a_task_in_the_way_of_a_body_is_replaced_by_its_parts(job: Job):
    parts = (np.array([[0.0, 0.0], [1.0, 0.0]]), np.array([[3.0, 0.0], [4.0, 0.0]]))
    blocked = [(np.array([[1.0, 0.0], [3.0, 0.0]]), 0.25)]
    open_ids, blocked_ids = job.replace("t00", parts, blocked, "robot-2")
    assert open_ids == ["t00.1", "t00.2"] and blocked_ids == ["t00.3"]
    assert job.tasks["t00"].state == REPLACED
    assert [job.tasks[t].state for t in open_ids] == [OPEN, OPEN]
    stuck = job.tasks["t00.3"]
    assert stuck.state == BLOCKED and stuck.blocked_by == "robot-2"
    assert stuck.task.area_m2 == 0.25  # the floor it puts out of reach
    assert job.tasks["t00.1"].task.area_m2 == pytest.approx(1.0)  # a quarter of a 4 m² task
    assert job.reopen("robot-1") == []  # another body
    assert job.reopen("robot-2") == ["t00.3"] and stuck.state == OPEN
