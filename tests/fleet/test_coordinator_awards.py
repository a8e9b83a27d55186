"""Award numbering across a coordinator restart, on a real router.

An agent takes an award only if it is numbered past the last one it took. A coordinator killed
between sending an award and its next periodic save of the robots came back numbering from an
older count, so every award it sent that robot was ignored and the robot's task was never
driven. The number is now saved before the award goes out, and an acknowledgement numbered past
the coordinator's own makes it send the queue again under a newer number.
"""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest
from waits import wait_until

from fleet.bus import Bus
from fleet.config import resolve_world
from fleet.coordinator.planning import TaskPlanner
from fleet.coordinator.service import Coordinator
from fleet.coordinator.store import JobStore
from fleet.params import load_fleet_config
from fleet.plausible import Bounds
from fleet.protocol import Award, AwardAck
from fleet.supervisor.launcher import free_port
from fleet.world import load_world
from planners.auction import Task

pytestmark = pytest.mark.timeout(60)


def _coordinator(bus: Bus, store: JobStore) -> Coordinator:
    cfg = load_fleet_config()
    planner = TaskPlanner(load_world(resolve_world("small"), cfg.robot.radius), cfg)
    coord = Coordinator(bus, planner, 1, cfg.coordinator, store, bounds=Bounds.of(cfg))
    path = np.array([[0.5, 0.5], [1.5, 0.5]])
    coord.job.add_tasks((Task("t00", path, 1.0, 4.0, (1,)),))
    robot = coord.job.robot("robot-0")
    robot.ready, robot.xy = True, (0.5, 0.5)
    coord.job.award("t00", "robot-0", False)
    coord.phase = "cleaning"
    return coord


def test_award_numbers_survive_a_restart_and_an_agent_ahead_is_caught_up(
    router_endpoint: str, tmp_path: Path
) -> None:
    fleet = f"t{free_port()}"
    awards: list[Award] = []
    lock = threading.Lock()

    def on_award(_key: str, msg: Award) -> None:
        with lock:
            awards.append(msg)

    with (
        Bus("coordinator", "coordinator", connect=[router_endpoint], fleet=fleet) as cbus,
        Bus("agent", "robot-0", connect=[router_endpoint], fleet=fleet) as abus,
    ):
        abus.subscribe(abus.keys.award("robot-0"), Award, on_award)
        store = JobStore(tmp_path / "job.sqlite")
        coord = _coordinator(cbus, store)

        def send_again() -> bool:
            """Send the queue under a new number until one has crossed the router."""
            coord.awards.sent.pop("robot-0", None)
            coord.awards.send()
            return bool(awards)

        assert wait_until(send_again), "no award crossed the router"
        first = awards[0]
        assert first.tasks == ["t00"] and first.robot == "robot-0"
        sent = coord.job.robots["robot-0"].award_seq
        store.close()

        # the number is on disk as soon as the award is out, not at the next periodic save
        again = JobStore(tmp_path / "job.sqlite")
        restarted = _coordinator(cbus, again)
        again.load_job(restarted.job)
        assert restarted.job.robots["robot-0"].award_seq == sent

        # an agent that took award 41 (from an older count) acknowledges it: the queue goes out
        # again numbered past 41
        with lock:
            awards.clear()
        restarted._on_ack(cbus.keys.ack("robot-0"), AwardAck(0.0, 41, "robot-0"))
        restarted.awards.send()
        assert wait_until(lambda: any(a.seq > 41 for a in awards)), [a.seq for a in awards]
        newest = max(awards, key=lambda a: a.seq)
        assert newest.tasks == ["t00"]
        again.close()
