"""Exploring, a part of the coordinator: the cleaning coordinator's market, loop and store,
with the robots' merged maps in place of the floor plan (:mod:`fleet.coordinator.exploring`).
It composes with the others: with batteries, robots go to charge while they explore.

What changes: no floor plan is served on ``coord/map`` (a robot prices travel on its own SLAM
map, unknown cells counted as free), the merged map as it grows is served on
``coord/explored`` instead (for the live view); the robots' map patches are heard; every
``coordinator.explore_every_s`` sim seconds the maps are merged and the frontier tasks
updated, the update told as an ``explored`` event (known area, frontiers, each robot's goal);
a robot that started with no known pose sends its map in its own frame until that map is
placed on the merged one, and is then sent the placement (``coord/placement/<robot>``; events
``placed`` and ``unplaced``); the market sells only to robots without work, so each holds one
frontier at a time (Burgard et al. 2005 assign one target per robot), and sells the open
frontier tasks, each worth its discounted information gain; the job's work is over when the
explorer finds no new frontier with no task open or assigned.
"""

from __future__ import annotations

import math
import threading

from fleet.coordinator.exploring import Change, Explorer, Snapshot, fetch_whole_maps
from fleet.coordinator.job import Job
from fleet.coordinator.market import Cut
from fleet.coordinator.parts import Host, Part
from fleet.floor_map import pack_grid
from fleet.protocol import MapPatches, Placement, Request
from planners import auction
from planners.map_match import MapMatch

# sim seconds between two ``unplaced`` events of one robot
UNPLACED_EVERY_S = 10.0


class ExplorePart(Part):
    """The robots' merged maps, their frontiers sold as tasks, one to each robot without
    work."""

    working = "exploring"
    floor_plan = False

    def __init__(self, explorer: Explorer) -> None:
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
        # the exploring is over (:meth:`work_over`): no update after it
        self.over = False

    def wire(self, host: Host) -> None:
        self.host = host
        self.job, self.journal = host.job, host.journal

    # ---- the market's hooks -----------------------------------------------------------------

    def regions(self, first: bool, cut: Cut) -> tuple[bool, Cut]:
        """No regions, and no first allocation: frontiers are sold one at a time."""
        return False, tuple

    def may_win(self, lot: auction.Lot, robot: str) -> bool:
        """Only a robot without work may win: each drives to one frontier at a time (a robot
        with work bids all the same; its bid shows what it would pay)."""
        return self.job.current(robot) is None

    def lots(self) -> dict[str, auction.Lot]:
        return self.explorer.lots(self.job)

    # ---- the service's hooks ----------------------------------------------------------------

    def serve(self) -> None:
        """The robots' maps heard; no floor plan served (the robots price travel on their own
        maps), the merged map of the last update served on ``coord/explored`` instead (an
        error reply before the first)."""
        bus = self.host.bus
        bus.subscribe(bus.keys.all_robots("map"), MapPatches, self._on_map)
        bus.serve(bus.keys.explored_map(), Request, self._on_explored_query)

    def _on_explored_query(self, _req: Request) -> MapPatches:
        explored = self._explored
        if explored is None:
            raise LookupError("no robot has sent its map yet")
        return explored

    def make_tasks(self) -> bool:
        """No tour: the tasks are the frontiers the updates find."""
        with self.host.lock:
            self.journal.set_meta(expected_robots=self.host.expected, exploring=True)
        return True

    def _on_map(self, key: str, msg: MapPatches) -> None:
        host = self.host
        rid = host.keys.robot_of(key)
        with host.lock:
            if host.implausible(key, rid, msg.stamp):
                return
            self.explorer.maps.hear(rid, msg)

    def tick(self) -> None:
        """Every ``explore_every_s`` sim seconds: take what the update reads (it runs in
        :meth:`unlocked`); none once the exploring is over."""
        host = self.host
        if self.over:
            return
        if self.explorer.maps.missing and not (self._fetching and self._fetching.is_alive()):
            # on a thread of its own: the main loop holds the lock
            self._fetching = threading.Thread(
                target=fetch_whole_maps,
                args=(host.bus, self.explorer.maps, host.lock),
                daemon=True,
            )
            self._fetching.start()
        if self.journal.clock - self.explored_at < host.params.explore_every_s:
            return
        self.explored_at = self.journal.clock
        self._snapshot = self.explorer.snapshot(self.job)

    def unlocked(self) -> None:
        """The update due: the maps merged and the frontiers found without the lock, taken
        into the job with it."""
        snap, self._snapshot = self._snapshot, None
        survey = None if snap is None else self.explorer.survey(snap)
        if survey is not None:
            with self.host.lock:
                self._take(self.explorer.apply(self.job, survey))

    def _take(self, change: Change) -> None:
        """Save and tell what an update changed; withdraw the tasks gone from their robots."""
        self._explored = pack_grid(change.grid, self.journal.clock)
        self.journal.save_tasks(*(t.id for t in change.added))
        for tid, owner in change.gone:
            self.journal.event("withdrawn", owner or "", tid, "its frontier vanished")
            self.journal.save_tasks(tid)
        gone = [tid for tid, _ in change.gone]
        host = self.host
        host.dispatcher.cut(gone)
        host.awards.send()
        if change.added or gone:
            host.market.version += 1
            host.market.need_auction = True
            host.wake.set()
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
            self.host.bus.publish(self.host.keys.placement(rid), msg, control=True)
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

    def work_over(self, job: Job) -> bool:
        """No task open or assigned, and the last update, with every robot's map in and floor
        on the merged map, found no new frontier (``Explorer.finished``); once so, for good:
        the exploring ends there, as the job does without batteries (with them, the robots'
        trips home after it explore nothing more, and call no robot back)."""
        self.over = self.over or self.explorer.finished(job)
        return self.over
