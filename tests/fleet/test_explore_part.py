"""The exploring coordinator on a real router: an update that takes longer than a robot's
heartbeat timeout (merging the maps of a large home) does not make the coordinator deaf to its
robots, which would take them for lost."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import replace

import pytest
from test_coordinator_exploring import patches, room
from waits import wait_until

import fleet.coordinator.exploring as exploring
from fleet.bus import Bus
from fleet.coordinator.explore_part import ExplorePart
from fleet.coordinator.exploring import Explorer, MapPlanner
from fleet.coordinator.job import ALIVE
from fleet.coordinator.service import Coordinator
from fleet.params import load_fleet_config
from fleet.plausible import Bounds
from fleet.protocol import Clock, Heartbeat, PoseEstimate

pytestmark = pytest.mark.timeout(60)

CFG = load_fleet_config()
SLOW_MERGE_S = 2.5 * CFG.coordinator.heartbeat_timeout_s


def robot_and_clock(
    sim: Bus, agent: Bus, stop: threading.Event, also: Callable[[float], None] = lambda _t: None
) -> None:
    """robot-0 as a live agent sends them (heartbeat, pose and map at 10 Hz of wall time), and
    the simulator's clock at 4× real time; ``also(t)`` sends whatever else the test wants at
    each sim time ``t``."""
    k = agent.keys
    t, seq = 0.0, 0
    while not stop.is_set():
        seq += 1
        t += 0.4
        sim.publish(k.clock(), Clock(t, 4.0))
        agent.publish(k.robot("robot-0", "heartbeat"), Heartbeat(t, seq, True))
        agent.publish(k.robot("robot-0", "pose"), PoseEstimate(t, 1.6, 1.6, 0.0))
        # stamped with the clock, as an agent stamps its map: one stamped ahead of the clock
        # by more than the lag a receiver allows is dropped as implausible
        agent.publish(k.robot("robot-0", "map"), replace(patches(room(door=True), seq), stamp=t))
        also(t)
        time.sleep(0.1)


def test_a_slow_map_merge_loses_no_robot(
    buses: tuple[Bus, Bus, Bus], monkeypatch: pytest.MonkeyPatch
) -> None:
    cbus, sim, agent = buses
    real_merge = exploring.merge_maps
    merges: list[float] = []

    def slow_merge(*args, **kwargs):
        merges.append(time.monotonic())
        time.sleep(SLOW_MERGE_S)
        return real_merge(*args, **kwargs)

    monkeypatch.setattr(exploring, "merge_maps", slow_merge)
    explorer = Explorer(CFG, MapPlanner(CFG), None)
    parts = [ExplorePart(explorer)]
    service = Coordinator(
        cbus, explorer.planner, 1, CFG.coordinator, bounds=Bounds.of(CFG), parts=parts
    )
    stop = threading.Event()
    feeder = threading.Thread(target=robot_and_clock, args=(sim, agent, stop), daemon=True)
    feeder.start()
    runner = threading.Thread(target=service.run, args=(0.5,), daemon=True)
    try:
        assert wait_until(lambda: "robot-0" in service.job.robots), "robot-0's token not heard"
        runner.start()
        assert wait_until(lambda: len(merges) >= 3, timeout=30), f"{len(merges)} merges"
    finally:
        service.stop.set()
        stop.set()
        runner.join(10)
        feeder.join(5)
        service.close()
    # lost once, it would have rejoined as "rejoined"
    assert service.job.robots["robot-0"].liveness == ALIVE
