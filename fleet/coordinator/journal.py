"""What the coordinator tells of its job as it changes: events, and the job on disk.

Every change of the job is an event (planned, auction, awarded, done, lost, ...): kept in the
store, published on ``coord/events`` for the views and the report, and logged for the kinds an
operator looks for. Events and everything the coordinator sends are stamped with ``clock``, the
newest sim time it has heard from the simulator's clock (as the service believes it): the
coordinator has no clock of its own. Changed
tasks, plans, robots and counters go to the :class:`~fleet.coordinator.store.JobStore` when
there is one; without one (no ``--state``) the job lives in memory only.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

from fleet.coordinator.job import Job, RobotRecord
from fleet.coordinator.store import JobStore
from fleet.protocol import FleetEvent, Keys, Message, Plan

log = logging.getLogger("coordinator")

# publish(key, message, control): Bus.publish, or a test's stand-in
Publish = Callable[[str, Message, bool], None]

LOGGED = ("lost", "rejoined", "reassigned", "withdrawn", "resumed")


class Journal:
    """The job's record: its events, and its store when there is one."""

    def __init__(
        self,
        job: Job,
        store: JobStore | None,
        keys: Keys,
        publish: Publish,
        clock: float = 0.0,
    ) -> None:
        self.job = job
        self.store = store
        self.keys = keys
        self.publish = publish
        self.clock = clock

    def heard(self, stamp: float) -> None:
        """The sim time is ``stamp`` (or later)."""
        self.clock = max(self.clock, stamp)

    def event(self, kind: str, robot: str, task: str, detail: str) -> None:
        wall = time.time()
        if kind in LOGGED:
            log.info("%s %s %s %s", kind, robot, task, detail)
        if self.store is not None:
            self.store.add_event(wall, self.clock, kind, robot, task, detail)
        self.publish(
            self.keys.events(), FleetEvent(self.clock, wall, kind, robot, task, detail), True
        )

    def save_tasks(self, *ids: str) -> None:
        if self.store is not None:
            self.store.save_tasks([self.job.tasks[i] for i in ids])

    def clear_job(self) -> None:
        """The job finished and a new one starts: its tasks and plans leave the store."""
        if self.store is not None:
            self.store.clear_job()

    def save_robots(self, robots: list[RobotRecord]) -> None:
        if self.store is not None:
            self.store.save_robots(robots)

    def save_plan(self, robot: str, plan: Plan) -> None:
        if self.store is not None:
            self.store.save_plan(robot, plan)

    def add_bids(self, rows: list[tuple]) -> None:
        """(round, task, robot, marginal_s, total_s, reverse, won) rows of one auction round."""
        if self.store is not None:
            self.store.add_bids(rows)

    def set_meta(self, **values: object) -> None:
        if self.store is not None:
            self.store.set_meta(**values)
