"""The coordinator process: owns the job — who cleans what — and tells the robots.

Phases: ``gathering`` (waiting for the expected robots to report a pose), ``cleaning`` (plans
sent), ``done`` (every robot reported its plan finished). Plans go out reliably and are also
served on ``coord/plan/<id>`` so a late or restarted agent fetches its plan by query.
The split of the floor into per-robot work sits behind :class:`CoveragePlanner`
(``fleet/coordinator/planning.py``), so decomposition and auctions can replace it.
"""

from __future__ import annotations

import logging
import threading
import time

import numpy as np

from fleet.bus import Bus
from fleet.coordinator.planning import CoveragePlanner
from fleet.protocol import FleetState, Plan, PoseEstimate, Request, RobotStatus

log = logging.getLogger("coordinator")


class Coordinator:
    def __init__(self, bus: Bus, planner: CoveragePlanner, expected: int, grace_s: float) -> None:
        self.bus = bus
        self.keys = bus.keys
        self.planner = planner
        self.expected = expected
        self.grace_s = grace_s
        self.lock = threading.Lock()
        self.stop = threading.Event()
        self.starts: dict[str, tuple[float, float]] = {}
        self.plans: dict[str, Plan] = {}
        self.done: set[str] = set()
        self.phase = "gathering"
        self.clock = 0.0
        bus.subscribe(self.keys.all_robots("pose"), PoseEstimate, self._on_pose)
        bus.subscribe(self.keys.all_robots("status"), RobotStatus, self._on_status)
        bus.serve(self.keys.plan("*"), Request, self._on_plan_query)

    def _on_pose(self, key: str, msg: PoseEstimate) -> None:
        rid = self.keys.robot_of(key)
        with self.lock:
            self.clock = max(self.clock, msg.stamp)
            self.starts.setdefault(rid, (msg.x, msg.y))

    def _on_status(self, key: str, msg: RobotStatus) -> None:
        rid = self.keys.robot_of(key)
        with self.lock:
            plan = self.plans.get(rid)
            if (
                plan is not None
                and msg.state == "done"
                and msg.task == plan.task
                and rid not in self.done
            ):
                self.done.add(rid)
                log.info("%s finished %s", rid, plan.task)

    def _on_plan_query(self, req: Request) -> Plan:
        with self.lock:
            plan = self.plans.get(req.sender)
        if plan is None:
            raise LookupError(f"no plan for {req.sender} yet")
        return plan

    def _assign(self) -> None:
        with self.lock:
            starts = dict(sorted(self.starts.items()))
        t0 = time.perf_counter()
        paths = self.planner.plan(starts)
        log.info(
            "planned %d robots in %.2f s: %s",
            len(paths),
            time.perf_counter() - t0,
            ", ".join(f"{r}: {len(p)} waypoints" for r, p in paths.items()),
        )
        with self.lock:
            for i, (rid, path) in enumerate(paths.items()):
                plan = Plan(self.clock, i + 1, f"coverage-{rid}", np.asarray(path, dtype=float))
                self.plans[rid] = plan
                if len(path) == 0:
                    self.done.add(rid)
            self.phase = "cleaning"
        for rid, plan in self.plans.items():
            self.bus.publish(self.keys.plan(rid), plan, control=True)

    def run(self) -> None:
        gather_start = time.monotonic()
        while not self.stop.is_set():
            with self.lock:
                n = len(self.starts)
                phase = self.phase
            if phase == "gathering":
                waited = time.monotonic() - gather_start
                if n >= self.expected or (n > 0 and waited > self.grace_s):
                    if n < self.expected:
                        log.warning(
                            "only %d of %d robots reported; planning for them", n, self.expected
                        )
                    self._assign()
            elif phase == "cleaning":
                with self.lock:
                    if self.done >= set(self.plans):
                        self.phase = "done"
                        log.info("all robots finished: the floor is clean")
                # Re-send plans now and then, so an agent that missed one catches up.
                for rid, plan in list(self.plans.items()):
                    if rid not in self.done:
                        self.bus.publish(self.keys.plan(rid), plan, control=True)
            with self.lock:
                state = FleetState(
                    self.clock, self.phase, sorted(self.plans or self.starts), sorted(self.done)
                )
            self.bus.publish(self.keys.coord_state(), state, control=True)
            self.stop.wait(0.5)
