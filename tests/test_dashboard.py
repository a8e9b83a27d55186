"""The live view without a bus: liveness, task counts, events, and the makespan it reports."""

from __future__ import annotations

import numpy as np
from rich.console import Console

from fleet.dashboard import FleetWatcher
from fleet.protocol import FleetEvent, FleetState, Keys, Plan, RobotStatus

STATUS = "fleet/default/robot/{}/status"


class _NoBus:
    keys = Keys()

    def subscribe(self, *_args: object) -> None:
        return None


def _watcher() -> FleetWatcher:
    w = FleetWatcher(_NoBus())  # type: ignore[arg-type]
    for rid in ("robot-0", "robot-1"):
        w._on_status(STATUS.format(rid), RobotStatus(10.0, "driving", "t03", 0.4, 3, 10, 4.2))
    return w


def test_a_lost_robot_and_the_latest_events_are_shown_but_routine_ones_are_not() -> None:
    w = _watcher()
    w._on_fleet("", FleetState(10.0, "cleaning", ["robot-0", "robot-1"], [], ["robot-1"], 1, 2, 3))
    w._on_event("", FleetEvent(10.0, 0.0, "awarded", "robot-0", "t04", ""))
    w._on_event("", FleetEvent(11.0, 0.0, "lost", "robot-1", "", "its liveliness token is gone"))
    console = Console(width=160, record=True)
    console.print(w.table(5.0))
    text = console.export_text()
    row = next(line for line in text.splitlines() if "robot-1" in line and "driving" in line)
    assert "lost" in row
    assert "alive" in next(line for line in text.splitlines() if "robot-0" in line)
    assert "tasks 1 open, 2 assigned, 3 done" in text
    assert "its liveliness token is gone" in text and "awarded" not in text
    lines = w.take_events()
    assert len(lines) == 1 and "lost" in lines[0]
    assert w.take_events() == []
    assert "lost=robot-1" in w.line(5.0)


def test_the_makespan_runs_from_the_first_plan_to_the_job_done() -> None:
    w = _watcher()
    w._on_plan("", Plan(4.0, 1, "t00", np.zeros((2, 2))))
    assert w.makespan() is None
    w._on_fleet("", FleetState(90.0, "done", ["robot-0"], ["robot-0"], [], 0, 0, 5))
    w._on_fleet("", FleetState(95.0, "done", ["robot-0"], ["robot-0"], [], 0, 0, 5))
    assert w.done and w.makespan() == 86.0
