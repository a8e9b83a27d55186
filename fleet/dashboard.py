"""Watching a run: collects coverage, robot status, collisions and true poses from the bus.

The dashboard reads truth (for metrics and the report picture) and commands nothing.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass, field

from rich.console import Group, RenderableType
from rich.table import Table
from rich.text import Text

from fleet.bus import Bus
from fleet.protocol import (
    Clock,
    Collision,
    CoverageSummary,
    FleetEvent,
    FleetState,
    Plan,
    RobotStatus,
    TruthPose,
)

TRACK_STEP_M = 0.05
EVENTS_SHOWN = 6
# routine events the view does not list; every event is in report.json
QUIET_EVENTS = ("awarded", "done", "joined")


@dataclass
class RobotView:
    status: RobotStatus | None = None
    track: list[tuple[float, float]] = field(default_factory=list)


class FleetWatcher:
    def __init__(self, bus: Bus) -> None:
        self.keys = bus.keys
        self.lock = threading.Lock()
        self.clock = 0.0
        self.coverage: CoverageSummary | None = None
        self.fleet: FleetState | None = None
        self.robots: dict[str, RobotView] = {}
        self.collisions: list[Collision] = []
        self.events: deque[FleetEvent] = deque(maxlen=EVENTS_SHOWN)
        self._unseen: list[FleetEvent] = []
        self.started_at: float | None = None
        self.finished_at: float | None = None
        k = self.keys
        bus.subscribe(k.clock(), Clock, self._on_clock)
        bus.subscribe(k.coverage(), CoverageSummary, self._on_coverage)
        bus.subscribe(k.coord_state(), FleetState, self._on_fleet)
        bus.subscribe(k.all_robots("status"), RobotStatus, self._on_status)
        bus.subscribe(k.all_robots("truth"), TruthPose, self._on_truth)
        bus.subscribe(k.collisions(), Collision, self._on_collision)
        bus.subscribe(k.plan("*"), Plan, self._on_plan)
        bus.subscribe(k.events(), FleetEvent, self._on_event)

    def _robot(self, key: str) -> RobotView:
        return self.robots.setdefault(self.keys.robot_of(key), RobotView())

    def _on_clock(self, _k: str, m: Clock) -> None:
        with self.lock:
            self.clock = max(self.clock, m.stamp)

    def _on_coverage(self, _k: str, m: CoverageSummary) -> None:
        with self.lock:
            self.coverage = m

    def _on_fleet(self, _k: str, m: FleetState) -> None:
        with self.lock:
            self.fleet = m
            if m.phase == "done" and self.finished_at is None:
                self.finished_at = m.stamp

    def _on_status(self, key: str, m: RobotStatus) -> None:
        with self.lock:
            self._robot(key).status = m

    def _on_truth(self, key: str, m: TruthPose) -> None:
        with self.lock:
            track = self._robot(key).track
            if not track or abs(track[-1][0] - m.x) + abs(track[-1][1] - m.y) >= TRACK_STEP_M:
                track.append((m.x, m.y))

    def _on_plan(self, _k: str, m: Plan) -> None:
        with self.lock:
            if self.started_at is None or m.stamp < self.started_at:
                self.started_at = m.stamp

    def _on_event(self, _k: str, m: FleetEvent) -> None:
        if m.kind not in QUIET_EVENTS:
            with self.lock:
                self.events.append(m)
                self._unseen.append(m)

    def take_events(self) -> list[str]:
        """The events (but the routine ones) since the last call, one line each."""
        with self.lock:
            unseen, self._unseen = self._unseen, []
        return [_event_line(e) for e in unseen]

    def _on_collision(self, _k: str, m: Collision) -> None:
        with self.lock:
            self.collisions.append(m)

    @property
    def done(self) -> bool:
        with self.lock:
            return self.fleet is not None and self.fleet.phase == "done"

    def makespan(self) -> float | None:
        """Sim seconds from the first plan given to the job done; None until it is."""
        with self.lock:
            if self.finished_at is None:
                return None
            return self.finished_at - (self.started_at or 0.0)

    def _tasks(self) -> str:
        f = self.fleet
        if f is None:
            return ""
        return f"tasks {f.tasks_open} open, {f.tasks_assigned} assigned, {f.tasks_done} done"

    def table(self, wall_s: float) -> RenderableType:
        """The live view: a robot table under the fleet's figures, then the latest events."""
        with self.lock:
            cov = self.coverage
            phase = self.fleet.phase if self.fleet else "starting"
            lost = set(self.fleet.lost) if self.fleet else set()
            rtf = self.clock / wall_s if wall_s > 0 else 0.0
            title = (
                f"fleet — {phase} — sim {self.clock:7.1f} s ({rtf:4.1f}× real time) — "
                f"coverage {100 * cov.coverage if cov else 0:5.1f} % — "
                f"repetition {100 * cov.repetition if cov else 0:4.1f} % — {self._tasks()}"
            )
            t = Table(title=title, expand=False)
            for col in (
                "robot",
                "live",
                "state",
                "task",
                "progress",
                "skipped",
                "distance m",
                "wall hits",
                "robot hits",
            ):
                t.add_column(
                    col,
                    justify="right" if col not in ("robot", "live", "state", "task") else "left",
                )
            hits = {}
            if cov is not None:
                hits = {
                    r: (int(cov.wall_collisions[i]), int(cov.robot_collisions[i]))
                    for i, r in enumerate(cov.robots)
                }
            for rid in sorted(self.robots):
                s = self.robots[rid].status
                w, r = hits.get(rid, (0, 0))
                live = "[red]lost[/]" if rid in lost else "alive"
                if s is None:
                    t.add_row(rid, live, "—", "", "", "", "", str(w), str(r))
                    continue
                t.add_row(
                    rid,
                    live,
                    s.state,
                    s.task,
                    f"{100 * s.progress:5.1f} %",
                    str(s.skipped),
                    f"{s.distance_m:7.1f}",
                    str(w),
                    str(r),
                )
            return Group(t, *(Text(_event_line(e)) for e in self.events))

    def line(self, wall_s: float) -> str:
        with self.lock:
            cov = self.coverage
            phase = self.fleet.phase if self.fleet else "starting"
            states = ", ".join(
                f"{rid}={v.status.state}:{100 * v.status.progress:.0f}%"
                + (f" ({v.status.skipped} skipped)" if v.status.skipped else "")
                for rid, v in sorted(self.robots.items())
                if v.status is not None
            )
            lost = f" lost={','.join(self.fleet.lost)}" if self.fleet and self.fleet.lost else ""
            return (
                f"[{wall_s:6.1f} s] {phase} sim={self.clock:.1f}s "
                f"coverage={100 * cov.coverage if cov else 0:.1f}% {self._tasks()}{lost} {states}"
            )


def _event_line(e: FleetEvent) -> str:
    when = time.strftime("%H:%M:%S", time.localtime(e.wall))
    return f"{when} sim {e.stamp:7.1f} s  {e.kind:<10} {e.robot:<10} {e.task:<8} {e.detail}"
