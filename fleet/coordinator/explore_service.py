"""The coordinator of an exploring fleet: the cleaning coordinator's market, loop and store,
with the robots' merged maps in place of the floor plan (:mod:`fleet.coordinator.exploring`).

What changes: no floor plan is served on ``coord/map`` (a robot prices travel on its own SLAM
map, unknown cells counted as free), the merged map as it grows is served on
``coord/explored`` instead (for the live view); the robots' map patches are heard; every
``coordinator.explore_every_s`` sim seconds the maps are merged and the frontier tasks
updated, the update told as an ``explored`` event (known area, frontiers, each robot's goal);
a robot that started with no known pose sends its map in its own frame until that map is
placed on the merged one, and is then sent the placement (``coord/placement/<robot>``; events
``placed`` and ``unplaced``); the market sells only to robots without work, so each holds one
frontier at a time (Burgard et al. 2005 assign one target per robot), and sells the open
frontier tasks, each worth its discounted information gain; the job is finished when the
explorer finds no new frontier with no task open or assigned.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable

from fleet.bus import Bus
from fleet.coordinator.exploring import Change, Explorer, Snapshot, fetch_whole_maps
from fleet.coordinator.market import Market
from fleet.coordinator.service import Coordinator
from fleet.coordinator.store import JobStore
from fleet.floor_map import pack_grid
from fleet.params import CoordinatorParams
from fleet.plausible import Bounds
from fleet.protocol import MapPatches, Placement, Request
from planners import auction
from planners.map_match import MapMatch

# sim seconds between two ``unplaced`` events of one robot
UNPLACED_EVERY_S = 10.0


class ExploringMarket(Market):
    """The market selling frontier tasks, one to each robot without work."""

    explorer: Explorer

    def _regions(self) -> tuple[bool, Callable[[], tuple[auction.Lot, ...]]]:
        return False, tuple

    def _untried(self, lot: auction.Lot, robot: str) -> bool:
        """Only a robot without work may win: each drives to one frontier at a time (a robot
        with work bids all the same; its bid shows what it would pay)."""
        return super()._untried(lot, robot) and self.job.current(robot) is None

    def _lots(self, regions: tuple[auction.Lot, ...]) -> dict[str, auction.Lot]:
        return self.explorer.lots(self.job)


class ExploringCoordinator(Coordinator):
    """The coordinator's loop and market on the robots' merged maps."""

    market_class = ExploringMarket
    working = "exploring"

    def __init__(
        self,
        bus: Bus,
        explorer: Explorer,
        expected: int,
        params: CoordinatorParams,
        store: JobStore | None = None,
        *,
        bounds: Bounds,
    ) -> None:
        self.explorer = explorer
        self.explored_at = -float("inf")
        self._fetching: threading.Thread | None = None
        # what the update due reads, taken under the lock for the loop's unlocked part
        self._snapshot: Snapshot | None = None
        # the merged map of the last update, packed for coord/explored
        self._explored: MapPatches | None = None
        # robots placed on the merged map (told once), and when each refusal was last told
        self._placed: set[str] = set()
        self._unplaced_told: dict[str, float] = {}
        super().__init__(bus, explorer.planner, expected, params, store, None, bounds=bounds)
        self.market.explorer = explorer  # type: ignore[attr-defined]
        bus.subscribe(self.keys.all_robots("map"), MapPatches, self._on_map)

    def _serve_floor(self) -> None:
        """No floor plan: the robots price travel on their own maps. The merged map of the
        last update is served on ``coord/explored`` (an error reply before the first)."""
        self.bus.serve(self.keys.explored_map(), Request, self._on_explored_query)

    def _on_explored_query(self, _req: Request) -> MapPatches:
        explored = self._explored
        if explored is None:
            raise LookupError("no robot has sent its map yet")
        return explored

    def _plan_tasks(self) -> None:
        with self.lock:
            self.journal.set_meta(expected_robots=self.expected, exploring=True)

    def _on_map(self, key: str, msg: MapPatches) -> None:
        rid = self.keys.robot_of(key)
        with self.lock:
            if self.implausible(key, rid, msg.stamp):
                return
            self.explorer.maps.hear(rid, msg)

    def _tick(self) -> None:
        """Every ``explore_every_s`` sim seconds: take what the update reads (it runs in
        :meth:`_unlocked`)."""
        if self.explorer.maps.missing and not (self._fetching and self._fetching.is_alive()):
            # on a thread of its own: the main loop holds the lock
            self._fetching = threading.Thread(
                target=fetch_whole_maps,
                args=(self.bus, self.explorer.maps, self.lock),
                daemon=True,
            )
            self._fetching.start()
        if self.journal.clock - self.explored_at < self.params.explore_every_s:
            return
        self.explored_at = self.journal.clock
        self._snapshot = self.explorer.snapshot(self.job)

    def _unlocked(self) -> None:
        """The update due: the maps merged and the frontiers found without the lock, taken
        into the job with it."""
        snap, self._snapshot = self._snapshot, None
        survey = None if snap is None else self.explorer.survey(snap)
        if survey is not None:
            with self.lock:
                self._take(self.explorer.apply(self.job, survey))

    def _take(self, change: Change) -> None:
        """Save and tell what an update changed; withdraw the tasks gone from their robots."""
        self._explored = pack_grid(change.grid, self.journal.clock)
        self.journal.save_tasks(*(t.id for t in change.added))
        for tid, owner in change.gone:
            self.journal.event("withdrawn", owner or "", tid, "its frontier vanished")
            self.journal.save_tasks(tid)
        gone = [tid for tid, _ in change.gone]
        self.dispatcher.cut(gone)
        self.awards.send()
        if change.added or gone:
            self.market.version += 1
            self.market.need_auction = True
            self.wake.set()
        goals = ", ".join(
            f"{rid} → {rec.task.id} ({rec.task.entry[0]:.1f}, {rec.task.entry[1]:.1f})"
            for rid in sorted(self.job.robots)
            if (rec := self.job.current(rid)) is not None
        )
        self.journal.event(
            "explored",
            "",
            "",
            f"known {change.known_m2:.1f} m², {change.frontiers} frontiers, "
            f"{len(change.added)} new, {len(gone)} gone; goals: {goals or 'none'}",
        )
        for rid, match in sorted(change.placements.items()):
            self._place(rid, match)

    def _place(self, rid: str, match: MapMatch) -> None:
        """Send a confident placement to its robot (again at every update while the robot's
        map stays in its own frame: the message may have been lost), told once as a
        ``placed`` event; a refusal is told as an ``unplaced`` event, at most every
        :data:`UNPLACED_EVERY_S` sim seconds."""
        t = match.transform
        clock = self.journal.clock
        if match.confident:
            msg = Placement(clock, rid, t.x, t.y, t.theta, match.score, match.overlap_m2)
            self.bus.publish(self.keys.placement(rid), msg, control=True)
            if rid not in self._placed:
                self._placed.add(rid)
                self.journal.event(
                    "placed",
                    rid,
                    "",
                    f"its map matched at ({t.x:.2f}, {t.y:.2f}, {math.degrees(t.theta):.1f}°), "
                    f"score {match.score:.2f}, overlap {match.overlap_m2:.1f} m²",
                )
        elif clock - self._unplaced_told.get(rid, -math.inf) >= UNPLACED_EVERY_S:
            self._unplaced_told[rid] = clock
            self.journal.event("unplaced", rid, "", f"its map is not placed: {match.reason}")

    def _finished(self) -> bool:
        return self.explorer.finished(self.job)
