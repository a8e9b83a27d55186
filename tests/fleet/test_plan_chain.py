"""A plan's chain and pieces, read the same way by the coordinator and the agent."""

from __future__ import annotations

import numpy as np

from fleet.plan_chain import (
    CHAIN_M,
    chain_length,
    chain_of,
    chain_pieces,
    chain_starts,
    current_task,
    cut_plan,
    piece_count,
    swept_pieces,
)
from fleet.protocol import Plan, decode, encode
from planners.auction import Task


def _line(n: int) -> np.ndarray:
    return np.column_stack([np.arange(n, dtype=float), np.zeros(n)])


def _chained() -> Plan:
    """Two waypoints of transit, then t01 over three pieces and t02 over two."""
    return Plan(0.0, 7, "t01", _line(8), 2, ["t01", "t02"], np.array([2, 5], dtype=np.int32))


def _task(tid: str, a: tuple[float, float], b: tuple[float, float]) -> Task:
    return Task(tid, np.array([a, b], dtype=float), 1.0, 1.0, (1,))


def test_a_plan_without_a_chain_drives_its_task_from_sweep_from() -> None:
    plan = Plan(0.0, 3, "t05", _line(5), 1)
    assert chain_of(plan) == ["t05"]
    assert chain_starts(plan).tolist() == [1]
    assert chain_pieces(plan) == [("t05", (0, 3))]


def test_each_chained_task_gets_its_slice_of_the_pieces_the_agent_reports() -> None:
    plan = _chained()
    assert chain_of(plan) == ["t01", "t02"]
    assert piece_count(len(plan.waypoints), plan.sweep_from) == 5
    assert chain_pieces(plan) == [("t01", (0, 3)), ("t02", (3, 5))]
    # the agent, past waypoint 5 (heading for 6), has swept t01's three pieces, none of t02's
    swept = swept_pieces(len(plan.waypoints), plan.sweep_from, 6)
    assert swept.tolist() == [1, 1, 1, 0, 0]
    assert len(swept) == chain_pieces(plan)[-1][1][1]


def test_the_current_task_is_the_last_one_begun() -> None:
    plan = _chained()
    chain, starts = chain_of(plan), chain_starts(plan)
    assert current_task(chain, starts, 1) == "t01"  # on the transit
    assert current_task(chain, starts, 5) == "t01"  # heading for t02's first waypoint
    assert current_task(chain, starts, 6) == "t02"
    assert current_task(chain, starts, None) == ""
    assert current_task([], np.zeros(0, dtype=np.int32), 3) == ""


def test_a_cut_plan_ends_where_its_first_task_given_up_begins_and_stays_valid() -> None:
    cut = cut_plan(_chained(), 1)
    assert cut.plan_id == 7 and chain_of(cut) == ["t01"]
    assert cut.waypoints.tolist() == _line(6).tolist()
    assert chain_pieces(cut) == [("t01", (0, 3))]
    assert decode(encode(cut), Plan).chain_starts.tolist() == [2]


def test_queued_tasks_chain_while_each_begins_where_the_one_before_ends() -> None:
    a = _task("a", (0.0, 0.0), (1.0, 0.0))
    b = _task("b", (2.0, 0.0), (1.0, CHAIN_M / 2))  # driven backwards, it begins at a's end
    c = _task("c", (2.0, 0.0), (3.0, 0.0))
    far = _task("d", (5.0, 0.0), (6.0, 0.0))
    assert chain_length([(a, False), (b, True), (c, False)]) == 3
    assert chain_length([(a, False), (b, False), (c, False)]) == 1
    assert chain_length([(a, False), (far, False), (c, False)]) == 1
    assert chain_length([]) == 0


def test_a_piece_whose_far_waypoint_was_given_up_short_is_not_swept() -> None:
    # 6 waypoints, sweep from 1: pieces end at waypoints 2..5; heading for 5, 3 given up short
    swept = swept_pieces(6, 1, 5, missed=(3,))
    assert swept.tolist() == [1, 0, 1, 0]
    assert swept_pieces(6, 1, 5).tolist() == [1, 1, 1, 0]
