"""The coordinator on a stored map keeps it true: furniture moved since the map was made is put
on the map it plans on, and the work it affects is planned again.

Once the stored map is checked (:mod:`fleet.coordinator.map_watch`), the watch goes on every
``coordinator.map_check_every_s`` sim seconds: the robots' SLAM maps are fused (their log-odds
summed in the world's frame, where each starts, ``planners.map_merge.merge_maps``) and compared
with the map the coordinator plans on (``planners.map_change.find_changes``: blobs seen
occupied on its floor, or free on its obstacles, away from its walls and from the robots). Each
change found:

- is told in a ``map changed`` event: what, where and how big, in world metres;
- goes onto the planning map (new furniture occupied: the box its faces seen span, joined with
  what was found before less than a robot's width and clearance from it,
  ``planners.map_change.obstacle_cells``; furniture taken away free) and onto the stored map
  later looks compare with, so a change is told once (more of the same piece, seen later from
  another side, is a change of its own, and makes the piece whole);
- for new furniture: every open or assigned task whose path runs through it is taken back from
  its owner (what the owner swept of it stays swept: its remainder is what is taken back), cut
  where it runs into the furniture and joined round it where a transit gets round
  (``fleet.coordinator.market.plan_around``, as round a lost robot's body), and sold again;
- for furniture taken away: the freed floor is on the planning map (transits may cross it, and
  a tour planned after it sweeps what robot centres reach there) and no task is made for it (a
  task of its own cost more time than the floor it gained: ``git show e86d9fa:BENCHMARKS.md``,
  "Options off by default").
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from fleet.coordinator.market import plan_around
from fleet.coordinator.parts import Host
from fleet.params import CoordinatorParams
from planners.bodies import Rerouted
from planners.grid import GridMap, clearance
from planners.map_change import (
    ADDED,
    MapChange,
    MapChangeParams,
    find_changes,
    obstacle_cells,
    with_cells,
)
from planners.map_merge import LogOddsMap, Transform2D, merge_maps

MAP_CHANGED = "map changed"


def map_change_params(params: CoordinatorParams) -> MapChangeParams:
    """The ``coordinator.map_change_*`` fields."""
    return MapChangeParams(
        confidence=params.map_change_confidence,
        min_size_m=params.map_change_min_size_m,
        wall_margin_m=params.map_change_wall_margin_m,
        robot_clear_m=params.map_change_robot_clear_m,
    )


class MapChanges:
    """The stored map as the robots have shown it changed, and what each change re-plans."""

    def __init__(self, coordinator: Host, stored: GridMap, params: MapChangeParams) -> None:
        self.coordinator = coordinator
        self.stored = stored
        # the wall margin is kept from the map as it was stored, not from the furniture found
        # since: a piece's faces are seen one side at a time, and the side seen later (its far
        # face, 0.4 m off, say) must not be lost in the margin of the part found first
        self._base = stored
        self._stored_clearance = clearance(stored)
        self.params = params
        # the furniture moved in so far, each piece the cells of its box (world centres)
        self.obstacles: list[np.ndarray] = []

    def look(
        self, maps: Mapping[str, LogOddsMap], limits: tuple[float, float]
    ) -> tuple[MapChange, ...]:
        """Compare the robots' ``maps`` (log-odds clamped to ``limits``) with the map as
        changed so far, and take each change found (:meth:`take`); the changes taken."""
        if not maps:
            return ()
        fused = merge_maps(list(maps.values()), [Transform2D.identity()] * len(maps), limits)
        c = self.coordinator
        with c.lock:
            robots = [r.xy for r in c.job.robots.values() if r.xy is not None]
        found = find_changes(
            fused, self.stored, self.params, np.array(robots, float), self._stored_clearance
        )
        return tuple(change for change in found if self.take(change))

    def take(self, change: MapChange) -> bool:
        """Put ``change`` on the stored map and the planning map, tell it, and re-plan the
        tasks new furniture lies in the way of; whether it was taken: not while the tour is
        being planned (the next look finds it again)."""
        c = self.coordinator
        with c.lock:
            planner = c.planner
            if planner.planning:
                return False
            added = change.kind == ADDED
            cells, size = change.cells, change.cell_size
            if added:
                # pieces closer than a robot's width with its clearance: none passes between
                cells, joined = obstacle_cells(change, self.obstacles, 2 * planner.centre_clearance)
                self.obstacles = [o for i, o in enumerate(self.obstacles) if i not in joined]
                self.obstacles.append(cells)
            self.stored = with_cells(self.stored, cells, size, added)
            if not added:
                self._base = with_cells(self._base, cells, size, added)
                self._stored_clearance = clearance(self._base)
            planner.change_floor(with_cells(planner.grid, cells, size, added))
            c.journal.event(MAP_CHANGED, "", "", change.describe() + _planned(cells, size, added))
            if not added:
                # freed floor is only put on the map: a tour planned after it sweeps what robot
                # centres reach there (a rim the blob left keeps them out:
                # docs/notes/stored-maps.md); after the tour is cut, no task sweeps it
                return True
            self._plan_round(cells, size)
            c.market.awards.send()
            c.market.need_auction = True
            c.market.wake.set()
        return True

    def _plan_round(self, cells: np.ndarray, size: float) -> None:
        """Re-plan the tasks whose paths run through new furniture at ``cells`` (squares of
        ``size``); each path is rerouted once, the answer kept for ``plan_around``."""
        planner = self.coordinator.planner
        # a cell's corner lies this far from its centre
        radius = size / math.sqrt(2)
        ways: dict[bytes, Rerouted] = {}

        def reroute(path: np.ndarray) -> Rerouted:
            key = path.tobytes()
            if key not in ways:
                ways[key] = planner.reroute(path)
            return ways[key]

        def through(path: np.ndarray) -> bool:
            return planner.near(path, cells, radius) and reroute(path).changed

        plan_around(
            self.coordinator.market,
            through,
            "",
            "runs through furniture the stored map does not have",
            "round furniture the stored map does not have",
            reroute,
        )


def _planned(cells: np.ndarray, size: float, added: bool) -> str:
    """What goes on the planning map, in words: the box of new furniture."""
    if not added:
        return ""
    (x0, y0), (x1, y1) = cells.min(axis=0) - size / 2, cells.max(axis=0) + size / 2
    return f"; planned round as x {x0:.2f}–{x1:.2f}, y {y0:.2f}–{y1:.2f}"
