"""Commitments, bids, winner determination and offline allocation of SSI auctions."""

from __future__ import annotations

import numpy as np
import pytest

from planners.auction import (
    Bid,
    Commitment,
    Task,
    allocate,
    make_bid,
    makespan,
    regions,
    task_lot,
    winner,
)


def straight(speed: float = 1.0):
    """Travel in straight lines at ``speed``: seconds from a point to each of K points."""

    def travel(start: np.ndarray, targets: np.ndarray) -> np.ndarray:
        return np.hypot(*(np.asarray(targets).reshape(-1, 2) - start).T) / speed

    return travel


def _corridor(n: int = 6) -> list[Task]:
    """n one-metre tasks end to end along y = 0 from x = 0, each driven left to right."""
    return [Task(f"t{k:02d}", np.array([[k, 0.0], [k + 1, 0.0]]), 0.3, 1.0, (1,)) for k in range(n)]


def _ends() -> dict[str, Commitment]:
    """Robot a just left of the corridor, robot b just right of it."""
    return {"a": Commitment((-1.0, 0.0)), "b": Commitment((7.0, 0.0))}


def test_a_commitment_ends_where_its_last_task_ends_and_sums_its_times():
    idle = Commitment((1.0, 2.0))
    assert idle.end == (1.0, 2.0)
    assert idle.total_s == 0.0
    busy = Commitment((1.0, 2.0), current_s=5.0, current_end=(3.0, 2.0))
    assert busy.end == (3.0, 2.0)
    more = busy.with_task(np.array([4.0, 2.0]), (4.0, 6.0), 10.0, 1.0)
    assert more.end == (4.0, 6.0)
    assert more.total_s == pytest.approx(16.0)
    assert busy.queued == ()
    assert isinstance(more.queued[0][0][0], float)


def test_a_won_bid_appends_its_task_in_the_bid_direction():
    held = Commitment((0.0, 0.0), current_s=2.0, current_end=(0.0, 1.0))
    bid = Bid("t03", "a", marginal_s=7.0, total_s=9.0, reverse=True)
    after = held.won(bid, np.array([5.0, 1.0]), np.array([1.0, 1.0]), 6.0)
    assert after.queued == (((1.0, 1.0), (5.0, 1.0), 6.0, 1.0),)
    assert after.end == (5.0, 1.0)
    assert after.total_s == pytest.approx(bid.total_s)


def test_a_bid_takes_the_nearer_end_of_the_task():
    travel = straight(0.5)
    entry, exit_ = np.array([0.0, 0.0]), np.array([4.0, 0.0])
    near_exit = Commitment((5.0, 0.0))
    bid = make_bid("a", "t01", entry, exit_, 8.0, near_exit, travel)
    assert bid.reverse
    assert bid.marginal_s == pytest.approx(2.0 + 8.0)
    assert bid.total_s == pytest.approx(10.0)
    near_entry = Commitment((9.0, 9.0), current_s=3.0, current_end=(-1.0, 0.0))
    bid = make_bid("b", "t01", entry, exit_, 8.0, near_entry, travel)
    assert (bid.task, bid.robot, bid.reverse) == ("t01", "b", False)
    assert bid.marginal_s == pytest.approx(2.0 + 8.0)
    assert bid.total_s == pytest.approx(3.0 + 10.0)


def test_a_bid_is_priced_from_the_end_of_the_queue():
    queued = Commitment((0.0, 0.0)).with_task((0.0, 0.0), (10.0, 0.0), 20.0, 0.0)
    bid = make_bid("a", "t02", np.array([10.0, 3.0]), np.array([0.0, 3.0]), 5.0, queued, straight())
    assert not bid.reverse
    assert bid.marginal_s == pytest.approx(3.0 + 5.0)
    assert bid.total_s == pytest.approx(20.0 + 8.0)


def test_what_a_task_is_worth_beyond_its_work_is_taken_off_its_bid():
    # Burgard et al. 2005: a far goal worth more can beat a near one worth less
    at = Commitment((0.0, 0.0))
    near = make_bid("a", "f1", np.array([2.0, 0.0]), np.array([2.0, 0.1]), 0.0, at, straight(), 1.0)
    far = make_bid("a", "f2", np.array([5.0, 0.0]), np.array([5.0, 0.1]), 0.0, at, straight(), 6.0)
    assert near.marginal_s == pytest.approx(2.0 - 1.0)
    assert far.marginal_s == pytest.approx(5.0 - 6.0) and far.total_s == far.marginal_s
    assert winner([near, far]).task == "f2"


BIDS = [
    Bid("t1", "a", marginal_s=5.0, total_s=50.0, reverse=False),
    Bid("t2", "b", marginal_s=9.0, total_s=20.0, reverse=True),
    Bid("t1", "c", marginal_s=7.0, total_s=30.0, reverse=False),
]


def test_minimax_takes_the_lowest_total():
    assert winner(BIDS) == BIDS[1]
    assert winner(iter(BIDS)) == BIDS[1]


def test_ties_go_to_the_lower_marginal_cost_then_robot_then_task():
    tied = [
        Bid("t2", "b", 4.0, 10.0, False),
        Bid("t1", "b", 4.0, 10.0, False),
        Bid("t9", "a", 6.0, 10.0, False),
        Bid("t3", "c", 3.0, 10.0, True),
    ]
    assert winner(tied) == tied[3]
    assert winner(tied[:3]) == tied[1]


def test_no_bids_no_winner():
    assert winner([]) is None


def test_minimax_gives_each_robot_the_near_half_of_the_corridor():
    tasks, robots = _corridor(), _ends()
    got = allocate(tasks, robots, straight())
    assert got == {
        "a": [("t00", False), ("t01", False), ("t02", False)],
        "b": [("t05", True), ("t04", True), ("t03", True)],
    }
    assert makespan(got, tasks, robots, straight()) == pytest.approx(1.0 + 3.0)


def test_the_allocation_does_not_depend_on_the_order_of_tasks_or_robots():
    tasks, robots = _corridor(), _ends()
    rng = np.random.default_rng(3)
    base = allocate(tasks, robots, straight())
    for _ in range(3):
        shuffled = [tasks[i] for i in rng.permutation(len(tasks))]
        flipped = dict(reversed(list(robots.items())))
        assert allocate(shuffled, flipped, straight()) == base


def test_busy_robots_are_priced_from_their_commitments():
    tasks = _corridor(2)
    robots = {
        "a": Commitment((0.0, 0.0), current_s=100.0, current_end=(0.0, 0.0)),
        "b": Commitment((20.0, 0.0)),
    }
    got = allocate(tasks, robots, straight())
    # b drives 18 m to t01's exit rather than wait for a's 100 s
    assert got == {"a": [], "b": [("t01", True), ("t00", True)]}
    assert makespan(got, tasks, robots, straight()) == pytest.approx(100.0)
    assert makespan({}, tasks, {}, straight()) == 0.0


def _chain(times: list[float]) -> list[Task]:
    xs = np.concatenate([[0.0], np.cumsum(times)])
    return [
        Task(f"t{i:02d}", np.array([[xs[i], 0.0], [xs[i + 1], 0.0]]), 1.0, t, (1,))
        for i, t in enumerate(times)
    ]


def test_regions_cut_the_tour_into_runs_of_about_equal_time() -> None:
    tasks = _chain([10.0, 10.0, 30.0, 10.0, 10.0, 10.0, 20.0, 10.0])
    lots = regions(tasks, 3)
    # cuts at the boundaries nearest 1/3 and 2/3 of the 110 s: after 50 s and after 70 s
    assert [lot.tasks for lot in lots] == [
        ("t00", "t01", "t02"),
        ("t03", "t04"),
        ("t05", "t06", "t07"),
    ]
    assert [lot.time_s for lot in lots] == [50.0, 20.0, 40.0]
    assert sum(len(lot.tasks) for lot in lots) == len(tasks)
    assert [t for lot in lots for t in lot.tasks] == [t.id for t in tasks]
    for lot in lots:
        first, last = lot.tasks[0], lot.tasks[-1]
        assert np.allclose(lot.entry, tasks[int(first[1:])].entry)
        assert np.allclose(lot.exit, tasks[int(last[1:])].exit)


def test_regions_never_leave_a_robot_an_empty_run() -> None:
    tasks = _chain([100.0, 1.0, 1.0])
    lots = regions(tasks, 3)
    assert [lot.tasks for lot in lots] == [("t00",), ("t01",), ("t02",)]
    assert len(regions(tasks, 5)) == 3
    assert regions([], 2) == ()
    with pytest.raises(ValueError, match="k must be"):
        regions(tasks, 0)


def test_a_single_task_lot_is_the_task() -> None:
    task = _chain([5.0])[0]
    lot = task_lot(task)
    assert lot.id == lot.tasks[0] == "t00" and lot.time_s == 5.0
    assert np.allclose(lot.entry, task.entry) and np.allclose(lot.exit, task.exit)
