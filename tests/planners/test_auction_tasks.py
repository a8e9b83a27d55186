"""Tasks of the market: a coverage tour cut into tasks, and the remainders of tasks."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
from robots import ROBOT

from fleet.config import resolve_world
from fleet.params import load_fleet_config
from fleet.world import load_world
from planners.auction import Task, ahead_of, remainder, split_tour
from planners.auction.tasks import CUT_WINDOW, task_time
from planners.coverage import CoverageParams, plan_coverage
from planners.grid import GridMap

PARAMS = CoverageParams()
RES = 0.05


def _open_floor(rows: int = 80, cols: int = 200) -> tuple[GridMap, np.ndarray]:
    occ = np.zeros((rows, cols), dtype=bool)
    return GridMap(occ, np.zeros_like(occ), RES, (0.0, 0.0)), np.ones(occ.shape, np.int32)


def _lanes(x0: float, x1: float, ys: np.ndarray) -> np.ndarray:
    """Boustrophedon lanes between x0 and x1 at heights ys, the first left to right."""
    pts = []
    for k, y in enumerate(ys):
        a, b = (x0, x1) if k % 2 == 0 else (x1, x0)
        pts += [(a, y), (b, y)]
    return np.array(pts)


def _time(path: np.ndarray) -> float:
    return task_time(path, PARAMS, ROBOT)


def _joined(tasks: tuple[Task, ...]) -> np.ndarray:
    return np.vstack([tasks[0].path] + [t.path[1:] for t in tasks[1:]])


def test_tasks_share_their_boundaries_and_together_are_the_path():
    grid, labels = _open_floor()
    path = _lanes(0.3, 9.0, np.arange(0.3, 3.6, 0.3))
    tasks = split_tour(path, labels, grid, 40.0, PARAMS, ROBOT)
    assert len(tasks) > 3
    assert [t.id for t in tasks] == [f"t{k:02d}" for k in range(len(tasks))]
    for a, b in itertools.pairwise(tasks):
        assert np.array_equal(a.exit, b.entry)
    assert np.array_equal(_joined(tasks), path)
    assert sum(t.pieces for t in tasks) == len(path) - 1


def test_every_task_but_the_last_takes_about_the_target_time():
    grid, labels = _open_floor()
    # short lanes: vertices every few seconds, so a cut can land close to its target
    path = _lanes(0.3, 2.3, np.arange(0.3, 3.9, 0.3))
    target = 25.0
    tasks = split_tour(path, labels, grid, target, PARAMS, ROBOT)
    assert len(tasks) >= 4
    for t in tasks[:-1]:
        assert (1 - CUT_WINDOW) * target - 6 <= t.time_s <= (1 + CUT_WINDOW) * target + 2
    assert 0 < tasks[-1].time_s <= (1 + CUT_WINDOW) * target + 2
    whole = _time(path)
    # the turn at each cut (half a turn in place here) belongs to neither task
    half_turn = np.pi / ROBOT.max_vel_theta + ROBOT.max_vel_theta / ROBOT.acc_lim_theta
    assert whole - half_turn * (len(tasks) - 1) <= sum(t.time_s for t in tasks) <= whole + 1e-9


def test_a_path_shorter_than_the_target_is_one_task():
    grid, labels = _open_floor()
    path = _lanes(0.3, 2.0, np.array([0.3, 0.6]))
    (task,) = split_tour(path, labels, grid, 1000.0, PARAMS, ROBOT, prefix="r")
    assert task.id == "r00"
    assert np.array_equal(task.path, path)
    assert task.time_s == pytest.approx(_time(path))
    assert task.area_m2 == pytest.approx(2 * 1.7 * 0.3 + 0.3 * 0.3, rel=0.15)
    assert task.cells == (1,)


def _two_blocks() -> tuple[GridMap, np.ndarray, np.ndarray, int]:
    """Lanes on the left, a hop back over them to lanes on the right (across a strip that is
    no floor), and the index of the hop's first vertex."""
    grid, labels = _open_floor()
    labels[:, 80:100] = 0
    labels[:, 100:] = 2
    left = _lanes(0.3, 3.8, np.arange(0.3, 2.2, 0.3))
    right = _lanes(5.2, 9.5, np.arange(0.3, 2.2, 0.3))
    return grid, labels, np.vstack([left, right]), len(left) - 1


def test_the_cut_lands_on_the_long_hop_within_the_window():
    grid, labels, path, hop = _two_blocks()
    before = _time(path[: hop + 1])
    # the hop's start lies 15 % before the target: inside the window, not at the target
    tasks = split_tour(path, labels, grid, before / 0.85, PARAMS, ROBOT)
    assert len(tasks[0].path) - 1 in (hop, hop + 1)
    # cut after the hop: its end reaches into the right block's floor
    assert tasks[0].cells[0] == 1
    assert tasks[1].cells == (2,)
    # the hop sweeps nothing new: the tasks' areas are the two blocks of lanes
    assert tasks[0].area_m2 + tasks[1].area_m2 == pytest.approx(
        (3.5 + 0.3) * 2.1 + (4.3 + 0.3) * 2.1, rel=0.1
    )


def test_a_hop_outside_the_window_does_not_draw_the_cut():
    grid, labels, path, hop = _two_blocks()
    before = _time(path[: hop + 1])
    tasks = split_tour(path, labels, grid, before / 1.6, PARAMS, ROBOT)
    assert len(tasks[0].path) - 1 < hop
    assert abs(tasks[0].time_s - before / 1.6) <= CUT_WINDOW * before / 1.6


@pytest.mark.parametrize(
    ("target", "path", "word"),
    [
        (0.0, _lanes(0, 1, np.array([0.3])), "target_s"),
        (-5.0, _lanes(0, 1, np.array([0.3])), "target_s"),
        (10.0, np.array([[0.5, 0.5]]), "path"),
        (10.0, np.zeros((3, 3)), "path"),
    ],
)
def test_bad_arguments_are_named(target, path, word):
    grid, labels = _open_floor()
    with pytest.raises(ValueError, match=word):
        split_tour(path, labels, grid, target, PARAMS, ROBOT)


@pytest.fixture(scope="module")
def small_world():
    """The small world planned like the coordinator plans it, with one robot from the dock."""
    cfg = load_fleet_config()
    world = load_world(resolve_world("small"), cfg.robot.radius)
    grid = world.grid(0.025)
    params = dataclasses.replace(cfg.coverage, overlap=cfg.coordinator.lane_overlap)
    x, y = world.start_poses(1, cfg.robot.radius)[0][:2]
    clearance = cfg.coordinator.wall_clearance
    plan = plan_coverage(grid, [(float(x), float(y))], params, cfg.robot, wall_clearance=clearance)
    return grid, params, plan


def test_the_small_world_tour_splits_into_tasks_of_its_cells(small_world):
    grid, params, plan = small_world
    path = plan.paths[0]
    tasks = split_tour(path, plan.cell_labels, grid, 30.0, params, ROBOT)
    assert len(tasks) >= 4
    assert np.array_equal(_joined(tasks), path)
    whole = task_time(path, params, ROBOT)
    total = sum(t.time_s for t in tasks)
    # a cut drops the turn in place at it, or, where the path drives through, adds a stop
    cuts = len(tasks) - 1
    half_turn = np.pi / ROBOT.max_vel_theta + ROBOT.max_vel_theta / ROBOT.acc_lim_theta
    stop = ROBOT.max_vel_x / ROBOT.acc_lim_x
    assert whole - half_turn * cuts - 1e-9 <= total <= whole + stop * cuts + 1e-9
    labels = set(np.unique(plan.cell_labels[plan.cell_labels > 0]).tolist())
    for t in tasks:
        assert t.cells and set(t.cells) <= labels
        assert list(t.cells) == sorted(set(t.cells))
    assert set().union(*(t.cells for t in tasks)) == labels
    area = plan.cleanable.sum() * grid.resolution**2
    assert sum(t.area_m2 for t in tasks) == pytest.approx(plan.metrics.total.coverage * area)


def _task() -> Task:
    path = _lanes(0.3, 2.3, np.array([0.3, 0.6, 0.9]))  # pieces: 2 m, 0.3, 2, 0.3, 2
    return Task("t07", path, 6.0, _time(path), (3, 4))


def test_a_task_swept_whole_leaves_no_remainder():
    assert remainder(_task(), np.ones(5, bool), "t07.1", PARAMS, ROBOT) is None


def test_a_task_not_swept_at_all_is_its_own_remainder():
    task = _task()
    rest = remainder(task, np.zeros(5, bool), "t07.1", PARAMS, ROBOT)
    assert rest is not None
    assert rest.id == "t07.1"
    assert np.array_equal(rest.path, task.path)
    assert rest.time_s == pytest.approx(task.time_s)
    assert rest.area_m2 == pytest.approx(task.area_m2)
    assert rest.cells == task.cells


def test_the_remainder_drives_again_the_swept_pieces_between_unswept_ones():
    task = _task()
    swept = np.array([True, False, True, False, True])
    rest = remainder(task, swept, "t07.2", PARAMS, ROBOT)
    assert rest is not None
    assert np.array_equal(rest.path, task.path[1:5])
    assert rest.pieces == 3
    assert rest.time_s == pytest.approx(_time(task.path[1:5]))
    assert rest.area_m2 == pytest.approx(6.0 * 0.6 / 6.6)
    assert rest.cells == (3, 4)


@pytest.mark.parametrize("n", [0, 4, 6])
def test_swept_flags_of_the_wrong_length_raise(n):
    with pytest.raises(ValueError, match="swept"):
        remainder(_task(), np.zeros(n, bool), "t07.1", PARAMS, ROBOT)


def test_what_a_robot_had_ahead_starts_past_where_it_stopped() -> None:
    task = Task("t05", np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 2.0]]), 5.0, 20.0, (1,))
    params = CoverageParams()
    rest = ahead_of(task, np.array([1.0, 0.1]), False, 0.5, "t05.1", params, ROBOT)
    assert rest is not None and rest.id == "t05.1"
    assert np.allclose(rest.path, [[1.5, 0.0], [3.0, 0.0], [3.0, 2.0]])
    assert rest.area_m2 == pytest.approx(5.0 * 3.5 / 5.0)
    # driven backwards from (3, 2): what was ahead is the start of the task, in its own direction
    back = ahead_of(task, np.array([2.9, 1.0]), True, 0.5, "t05.1", params, ROBOT)
    assert back is not None
    assert np.allclose(back.path, [[0.0, 0.0], [3.0, 0.0], [3.0, 0.5]])
    # stopped within reach of the end: nothing left
    assert ahead_of(task, np.array([3.0, 1.8]), False, 0.5, "t05.1", params, ROBOT) is None
