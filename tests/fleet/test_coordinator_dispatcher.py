"""The dispatcher without a bus: plans for the run of a robot's queue, cut and forgotten."""

from __future__ import annotations

import numpy as np
import pytest

from fleet.config import resolve_world
from fleet.coordinator.dispatcher import Dispatcher
from fleet.coordinator.job import Job
from fleet.coordinator.journal import Journal
from fleet.coordinator.planning import TaskPlanner
from fleet.coordinator.transits import PlannedTransit
from fleet.params import load_fleet_config
from fleet.plan_chain import chain_of
from fleet.protocol import Keys, Message, Plan
from fleet.world import load_world
from planners.auction import Task

KEYS = Keys("test")


def _task(tid: str, *points: tuple[float, float]) -> Task:
    return Task(tid, np.array(points, dtype=float), 1.0, 4.0, (1,))


@pytest.fixture(scope="module")
def planner() -> TaskPlanner:
    cfg = load_fleet_config()
    return TaskPlanner(load_world(resolve_world("small"), cfg.robot.radius), cfg)


def test_a_robot_gets_one_plan_for_the_run_of_its_queue_once_it_has_the_award(
    planner: TaskPlanner,
) -> None:
    cfg = load_fleet_config()
    job = Job(planner.params, planner.robot, planner.wall_clearance)
    # t01 begins where t00 ends, and t02 where t01 ends driven backwards; t03 is elsewhere
    job.add_tasks(
        (
            _task("t00", (1.0, 0.85), (1.5, 0.85)),
            _task("t01", (1.5, 0.85), (1.5, 1.3)),
            _task("t02", (1.0, 1.3), (1.5, 1.3)),
            _task("t03", (1.0, 2.0), (1.0, 1.5)),
        )
    )
    for tid, reverse in (("t00", False), ("t01", False), ("t02", True), ("t03", False)):
        job.award(tid, "robot-0", reverse)
    robot = job.robot("robot-0")
    robot.ready, robot.xy, robot.award_seq = True, planner.dock, 1
    sent: list[tuple[str, Message]] = []
    journal = Journal(job, None, KEYS, lambda key, msg, _control: sent.append((key, msg)))
    d = Dispatcher(journal, planner, None, cfg.coordinator, KEYS, journal.publish)

    d.dispatch()
    assert not [m for _, m in sent if isinstance(m, Plan)], "a plan before the award's ack"
    robot.acked_seq = 1
    d.dispatch()
    d.dispatch()
    plans = [(k, m) for k, m in sent if isinstance(m, Plan)]
    assert len(plans) == 1 and plans[0][0] == KEYS.plan("robot-0")
    plan = plans[0][1]
    assert chain_of(plan) == ["t00", "t01", "t02"]
    assert np.allclose(plan.waypoints[plan.sweep_from], (1.0, 0.85))
    assert np.allclose(plan.waypoints[-1], (1.0, 1.3))  # t02 driven backwards
    assert d.current("robot-0") is plan

    # t02 goes back to the market: the plan ends where t02 began, under the same id
    d.cut(["t02", "t03"])
    cut = sent[-1][1]
    assert isinstance(cut, Plan) and cut.plan_id == plan.plan_id
    assert chain_of(cut) == ["t00", "t01"]
    assert np.allclose(cut.waypoints[-1], (1.5, 1.3))
    # a robot keeps the task it drives: a withdrawn first task cuts nothing
    before = len(sent)
    d.cut(["t00"])
    assert len(sent) == before

    d.forget("robot-0")
    assert d.current("robot-0") is None


def test_a_wait_on_a_robot_standing_in_the_round_is_left_out_not_a_crash(
    planner: TaskPlanner,
) -> None:
    """A planned transit may order a robot after one that stands in the round (no work, stuck:
    planned round as an obstacle). That robot drives no plan of the round, so the wait is left
    out; the coordinator once crashed looking up its new plan id (KeyError)."""
    cfg = load_fleet_config()
    job = Job(planner.params, planner.robot, planner.wall_clearance)
    job.add_tasks((_task("t00", (1.0, 0.85), (1.5, 0.85)),))
    job.award("t00", "robot-0", False)
    robot = job.robot("robot-0")
    robot.ready, robot.xy, robot.award_seq, robot.acked_seq = True, planner.dock, 1, 1
    sent: list[tuple[str, Message]] = []
    journal = Journal(job, None, KEYS, lambda key, msg, _control: sent.append((key, msg)))
    d = Dispatcher(journal, planner, None, cfg.coordinator, KEYS, journal.publish)
    chain = d._unplanned()["robot-0"]
    points = np.array([planner.dock, (1.0, 0.85)], dtype=float)
    transit = PlannedTransit(points, ((1, "robot-5", 2), (1, "robot-1", 0)), np.zeros(2))
    d._send_plan("robot-0", chain, transit, {"robot-0": 7, "robot-1": 8})
    plan = sent[-1][1]
    assert isinstance(plan, Plan) and plan.plan_id == 7
    assert list(plan.wait_for) == ["robot-1"] and plan.wait_plan.tolist() == [8]
