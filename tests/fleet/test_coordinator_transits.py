"""The coordinator's transits in space and time: a round on the corridor world's transit graph
becomes waypoints a robot drives (starting where it stands, staircases straightened) with the
order of passage renumbered to them; robots that stand are planned around, not sent
anywhere."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fleet.bench.world_family import FAMILY, FamilyMember, layout, write_world
from fleet.config import resolve_world
from fleet.coordinator.planning import TaskPlanner
from fleet.coordinator.transits import TransitPlanner
from fleet.params import load_fleet_config
from fleet.world import load_world
from planners.auction import Task
from planners.polyline import count_turns


@pytest.fixture(scope="module")
def corridor() -> TransitPlanner:
    cfg = load_fleet_config()
    world = load_world(resolve_world("corridor"))
    planner = TaskPlanner(world, cfg)
    return TransitPlanner(world, cfg, "prioritized", planner.transit.clear)


def test_a_round_through_the_corridor(corridor: TransitPlanner) -> None:
    moving = {
        "robot-0": ((0.9, 1.5), (7.5, 2.5)),
        "robot-1": ((0.9, 0.8), (6.0, 0.5)),
        "robot-2": ((7.2, 1.5), (0.6, 2.5)),
    }
    plan, out = corridor.plan(10.0, moving, {"robot-3": (1.5, 2.5)})
    assert plan.status == "success", plan.message
    assert set(out) == set(moving)
    for rid, t in out.items():
        assert tuple(t.waypoints[0]) == moving[rid][0]
        assert np.all(np.diff(t.arrivals_s) > 0) and t.arrivals_s[0] == 10.0
        cells = next(x.cells for x in plan.transits if x.name == rid)
        assert len(t.waypoints) < len(set(cells)), "no cell point was dropped"
        for at, peer, passed in t.waits:
            assert peer in moving and peer != rid
            assert 0 < at < len(t.waypoints) and 0 <= passed < len(out[peer].waypoints)
    # robots crossing the one-lane corridor in opposite directions wait for each other
    assert out["robot-2"].waits or out["robot-0"].waits


def test_a_planned_transit_runs_into_its_task_without_a_cell_point_beside_it(
    corridor: TransitPlanner,
) -> None:
    """The goal cell's point lies up to half a cell beside or beyond the task's start; a robot
    sent through it turned in place there and again at the start. A transit whose goal lies in
    its route's last cell ends on the goal itself, and starts where the robot stands."""
    planner = TaskPlanner(load_world(resolve_world("corridor")), load_fleet_config())
    start, lane = (0.9, 1.5), np.linspace((7.3, 2.6), (8.3, 2.6), 5)
    _, out = corridor.plan(0.0, {"robot-0": (start, tuple(lane[0]))}, {})
    transit = out["robot-0"].waypoints
    waypoints, starts = planner.drive(start, [(Task("t01", lane, 1.0, 8.0, (1,)), False)], transit)
    leg = waypoints[: starts[0] + 1]
    assert np.allclose(leg[0], start) and np.allclose(leg[-1], lane[0])
    assert len(leg) == len(transit), "each point keeps the index the order of passage counts by"
    assert np.linalg.norm(leg[:-1] - lane[0], axis=1).min() > 0.3
    assert count_turns(leg, 45.0) == 1


def test_two_transits_to_one_point_end_in_two_cells(corridor: TransitPlanner) -> None:
    """Two lanes that begin at one point (a lane cut in two, its pieces sold to two robots):
    the round gives one robot the goal's cell and the other the next free cell. Only the first
    transit runs into the goal; the second ends on its own cell's point, from where its robot
    drives on once the first has gone (run on into the goal, both met on one point)."""
    goal = (2.2, 2.4)
    moving = {"robot-0": ((0.9, 1.5), goal), "robot-1": ((1.5, 0.6), goal)}
    plan, out = corridor.plan(0.0, moving, {})
    assert plan.status == "success", plan.message
    ends = {rid: tuple(t.waypoints[-1]) for rid, t in out.items()}
    on_goal = [rid for rid, end in ends.items() if np.allclose(end, goal)]
    assert len(on_goal) == 1, ends
    other = next(rid for rid in ends if rid not in on_goal)
    assert np.linalg.norm(np.subtract(ends[other], goal)) > 0.1


@pytest.mark.parametrize("member", FAMILY, ids=lambda m: m.name)
def test_every_room_of_a_generated_world_is_reached_from_every_start(
    member: FamilyMember, tmp_path: Path
) -> None:
    """The coordinator's transit graph joins what the coverage plan joins: on the family's
    narrowest corridor (0.45 m between faces) a graph on the simulator's 5 cm grid had no cell
    inside it, and a transit from one room to the other "could not be reached"."""
    cfg = load_fleet_config()
    world = load_world(write_world(member, tmp_path), cfg.robot.radius)
    transits = TransitPlanner(world, cfg, "prioritized", TaskPlanner(world, cfg).transit.clear)
    plan = layout(member)
    for start in plan.starts:
        for goal in plan.room_points:
            moving = {"robot-0": (tuple(start[:2]), tuple(goal))}
            result, out = transits.plan(0.0, moving, {})
            assert result.status == "success", (member.name, start, goal, result.message)
            assert np.allclose(out["robot-0"].waypoints[0], start[:2])
