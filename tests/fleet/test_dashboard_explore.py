"""The live view of an exploring fleet: the robots' merged map drawn as it grows (fetched from
the coordinator again and again), nothing of the true floor they have not mapped, and the
frontier each robot heads for."""

from __future__ import annotations

import numpy as np
import pytest
from waits import wait_until

from fleet.bus import Bus
from fleet.dashboard.model import EXPLORING, BusFeed, FleetWatcher
from fleet.dashboard.view import DIRTY, GOAL, WALL, plain, render_map
from fleet.floor_map import pack_grid
from fleet.protocol import (
    CoverageImage,
    FleetState,
    Keys,
    MapPatches,
    Plan,
    Request,
    TruthPose,
    decode,
)
from fleet.supervisor.launcher import free_port
from planners.grid import GridMap

KEYS = Keys()
RES = 0.05
# a 4 m × 3 m room drawn 40 × 15 characters: 0.1 m per column, 0.2 m per row, y 3 m on top
WIDTH, HEIGHT = 40, 15


def _room(known_up_to_x: float = 4.0) -> GridMap:
    """The room with walls one cell thick (all mapped), its floor known west of
    ``known_up_to_x`` only."""
    occupied = np.zeros((60, 80), dtype=bool)
    occupied[0, :] = occupied[-1, :] = occupied[:, 0] = occupied[:, -1] = True
    unknown = np.zeros_like(occupied)
    unknown[:, round(known_up_to_x / RES) :] = True
    return GridMap(occupied, unknown & ~occupied, RES, (0.0, 0.0))


def _truth() -> CoverageImage:
    """The simulator's cleaned area: all of the room's floor cleanable, nothing swept."""
    cleanable = np.zeros((60, 80), dtype=np.uint8)
    cleanable[1:-1, 1:-1] = 1
    return CoverageImage(
        0.0, RES, 0.0, 0.0, 60, 80, np.zeros(60 * 80, np.uint16), cleanable.ravel()
    )


def _watcher(phase: str) -> FleetWatcher:
    w = FleetWatcher()
    w.on_fleet(KEYS.coord_state(), FleetState(5.0, phase, ["robot-0"], []))
    w.on_cleaned(_truth())
    w.on_plan(KEYS.plan("robot-0"), Plan(5.0, 1, "f003", np.array([[0.5, 1.5], [1.55, 2.1]])))
    return w


def _lines(w: FleetWatcher) -> list[str]:
    return plain(render_map(w.snapshot(), WIDTH, HEIGHT)).splitlines()


def test_exploring_the_view_draws_only_what_the_robots_mapped_and_each_robots_frontier() -> None:
    w = _watcher(EXPLORING)
    w.on_floor(decode(pack_grid(_room(known_up_to_x=2.0)).encode(), MapPatches))
    lines = _lines(w)
    # the known west half: walls and floor; the unknown east half: nothing of the true floor
    assert lines[0] == WALL * WIDTH and len(lines[7]) == WIDTH
    assert DIRTY in lines[7][:20] and set(lines[7][21:-1]) == {" "}, lines[7]
    # robot-0's frontier: the end of its plan, x 1.55 → column 15, y 2.1 → row 4
    assert lines[4][15] == GOAL
    # the map grows: the east half is drawn once mapped
    w.on_floor(decode(pack_grid(_room()).encode(), MapPatches))
    lines = _lines(w)
    assert DIRTY in lines[7][21:-1]


def test_before_any_map_only_a_cleaning_fleets_view_draws_the_true_floor() -> None:
    cleaning = _lines(_watcher("cleaning"))
    assert sum(line.count(DIRTY) for line in cleaning) > 400
    assert GOAL not in "".join(cleaning)
    w = _watcher(EXPLORING)
    w.on_truth(KEYS.robot("robot-0", "truth"), TruthPose(5.0, 0.5, 1.5, 0.0))
    exploring = _lines(w)
    assert DIRTY not in "".join(exploring) and "→" in "".join(exploring)
    # framed round the robot (a metre each way, x from −0.5 m), not round the true floor's
    # 4 m × 3 m (x from 0, where the robot at x 0.5 m would stand in column 5)
    assert min(line.find("→") for line in exploring if "→" in line) > 10


@pytest.mark.timeout(60)
def test_over_a_live_bus_the_view_fetches_the_merged_map_again_while_exploring(
    router_endpoint: str,
) -> None:
    served = [pack_grid(_room(known_up_to_x=1.0))]
    fleet = f"t{free_port()}"
    with (
        Bus("dashboard", "view", [router_endpoint], fleet) as view_bus,
        Bus("coordinator", "c", [router_endpoint], fleet) as coord,
    ):
        coord.serve(coord.keys.explored_map(), Request, lambda _r: served[-1])
        w = FleetWatcher()
        feed = BusFeed(view_bus, w, fetch=False)
        try:
            state = FleetState(1.0, EXPLORING, ["robot-0"], [])

            def heard() -> bool:
                # published again until heard, as the coordinator does every loop: the first
                # message can go before the router has the view's subscription
                coord.publish(coord.keys.coord_state(), state)
                return feed.pump() >= 0 and w.phase == EXPLORING

            assert wait_until(heard, poll=0.1), "no state heard"
            feed.fetch_once()
            assert w.floor is not None and w.floor.unknown[1:59, 30:79].all()
            served.append(pack_grid(_room(known_up_to_x=3.0)))
            feed.fetch_once()
            assert not w.floor.unknown[:60, 30:50].any(), "the grown map was not fetched again"
        finally:
            feed.close()
