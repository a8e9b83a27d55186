"""The coordinator's tasks and plans: one tour cut into tasks, and a won task driven."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from fleet.config import resolve_world
from fleet.coordinator.planning import TaskPlanner
from fleet.params import load_fleet_config
from fleet.world import load_world
from planners.auction import Task
from planners.polyline import path_length


@pytest.fixture(scope="module")
def small():
    cfg = load_fleet_config()
    world = load_world(resolve_world("small"), cfg.robot.radius)
    planner = TaskPlanner(world, cfg)
    return planner, planner.tasks()


def test_the_tasks_chain_into_one_tour_of_about_the_target_time(small):
    planner, tasks = small
    assert len(tasks) >= 4
    for a, b in itertools.pairwise(tasks):
        assert np.allclose(a.exit, b.entry)
    # the tour starts at the dock; every task but the last is near the target
    assert np.allclose(tasks[0].entry, planner.dock)
    times = np.array([t.time_s for t in tasks[:-1]])
    assert np.all(times > 0.5 * planner.target_s)
    assert np.all(times < 1.5 * planner.target_s)
    assert len({t.id for t in tasks}) == len(tasks)


def test_the_same_world_gives_the_same_tasks(small):
    planner, tasks = small
    again = planner.tasks()
    assert [t.id for t in again] == [t.id for t in tasks]
    assert all(np.array_equal(a.path, b.path) for a, b in zip(again, tasks, strict=True))


@pytest.mark.parametrize("reverse", [False, True])
def test_a_plan_is_a_transit_to_the_task_then_its_sweep(small, reverse):
    planner, tasks = small
    task = tasks[2]
    start = (float(planner.dock[0]), float(planner.dock[1]))
    waypoints, starts = planner.drive(start, [(task, reverse)])
    (sweep_from,) = starts
    sweep = task.path[::-1] if reverse else task.path
    assert np.allclose(waypoints[0], start)
    assert np.array_equal(waypoints[sweep_from:], sweep)
    # the transit keeps off the furniture: it is no shorter than the straight line
    transit = waypoints[: sweep_from + 1]
    assert path_length(transit) >= np.hypot(*(sweep[0] - np.array(start))) - 1e-9


def test_a_robot_at_the_task_entry_starts_sweeping_at_once(small):
    planner, tasks = small
    task = tasks[1]
    waypoints, starts = planner.drive(tuple(task.entry), [(task, False)])
    assert starts == [0]
    assert np.array_equal(waypoints, task.path)


def test_tasks_that_follow_on_are_one_plan_each_from_where_the_last_ends(small):
    planner, tasks = small
    run = tasks[1:4]
    waypoints, starts = planner.drive(tuple(planner.dock), [(t, False) for t in run])
    for task, a, b in zip(run, starts, [*starts[1:], len(waypoints) - 1], strict=True):
        assert np.array_equal(waypoints[a : b + 1], task.path)
    # backwards: last task first, each reversed, still one unbroken path
    back = [(t, True) for t in reversed(run)]
    waypoints, starts = planner.drive(tuple(run[-1].exit), back)
    assert starts[0] == 0
    assert np.array_equal(
        waypoints[starts[1] :], np.vstack([run[1].path[::-1], run[0].path[::-1][1:]])
    )


@pytest.fixture
def corridor():
    cfg = load_fleet_config()
    planner = TaskPlanner(load_world(resolve_world("corridor"), cfg.robot.radius), cfg)
    yield planner
    planner.set_bodies(np.zeros((0, 2)))


def test_a_body_in_the_only_way_cuts_the_far_room_off(corridor):
    """A body in the corridor, the only way between the two rooms: a plan from the west room
    to a task in the east room finds no way (ValueError: the dispatcher reports the task
    unreachable for that robot), a lane through the corridor falls apart into its two rooms'
    parts, and the corridor's floor is out of reach; without the body, the way is open."""
    east = Task("t09", np.array([[6.0, 0.5], [7.5, 0.5]]), 0.45, 3.0, (1,))
    west_xy = (1.0, 1.5)
    assert corridor.drive(west_xy, [(east, False)])[0].shape[1] == 2
    corridor.set_bodies(np.array([[4.0, 1.45]]))
    with pytest.raises(ValueError, match="no free path"):
        corridor.drive(west_xy, [(east, False)])
    through = np.array([[2.0, 1.45], [6.0, 1.45]])
    assert corridor.near_bodies(through)
    way = corridor.reroute(through)
    assert len(way.paths) == 2 and way.changed
    reach = corridor.body_radius + corridor.centre_clearance
    assert way.paths[0][:, 0].max() <= 4.0 - reach + 0.01
    assert way.paths[1][:, 0].min() >= 4.0 + reach - 0.01
    assert corridor.blocked_m2(way.dropped[0]) > 0.15  # the corridor's floor, 0.3 m wide
    corridor.set_bodies(np.zeros((0, 2)))
    assert corridor.drive(west_xy, [(east, False)])[0].shape[1] == 2


# the coordinator's one-robot tour on the built-in worlds: its repetition (its own figure, on
# its own floor; BENCHMARKS.md, "fleet bench coverage": home 28.7 %, small 26.0 %, corridor
# 21.4 %, corridor_wide 24.5 %) plus half a point
TOUR_REPETITION = {"home": 0.292, "small": 0.265, "corridor": 0.219, "corridor_wide": 0.25}


@pytest.mark.parametrize("name", sorted(TOUR_REPETITION))
def test_the_tour_resweeps_no_more_than_measured(name):
    cfg = load_fleet_config()
    planner = TaskPlanner(load_world(resolve_world(name), cfg.robot.radius), cfg)
    planner.tasks()
    tour = planner.meta["tour"]
    assert tour["coverage"] >= 0.995
    assert tour["repetition"] <= TOUR_REPETITION[name], tour
