"""The coordinator's transits in space and time: a round on the corridor world's transit graph
becomes waypoints a robot drives (starting where it stands, staircases straightened) with the
order of passage renumbered to them; robots that stand are planned around, not sent
anywhere."""

from __future__ import annotations

import numpy as np
import pytest

from fleet.config import resolve_world
from fleet.coordinator.planning import TaskPlanner
from fleet.coordinator.transits import TransitPlanner
from fleet.params import load_fleet_config
from fleet.world import load_world


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
