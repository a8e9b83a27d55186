"""The coordinator on a stored map (``--map``) checks that the map is the floor the robots see.

A stored map of another building (or of this one in another frame) would have the fleet drive
blind: lanes through walls, transits into furniture. The robots' own SLAM maps come in as
their changed tiles (``robot/<id>/map``, kept by :class:`fleet.coordinator.exploring.RobotMaps`;
a gap has the whole map fetched by query). Every ``coordinator.map_check_every_s`` sim seconds
each robot's map not yet judged is matched against the stored map
(``planners.map_check.check_map``), on a thread of its own (a match takes a tenth of a second
or more, which the market's lock should not wait for). Once more than half of the fleet's
robots agree with the map the watch ends, saying so in a ``map checked`` event; once more than
half differ, it tells why in a ``wrong map`` event that names the map file and stops the
coordinator, whose process then exits with
:data:`fleet.supervisor.fleet_processes.WRONG_MAP_EXIT`. A map accepted is watched on for furniture
moved since it was made (:mod:`fleet.coordinator.map_changes`).
"""

from __future__ import annotations

import logging
import threading
from pathlib import Path

from fleet.bus import Bus
from fleet.coordinator.exploring import RobotMaps, fetch_whole_maps, logit
from fleet.coordinator.map_changes import MapChanges, map_change_params
from fleet.coordinator.parts import Host, Part
from fleet.params import FleetConfig
from fleet.protocol import MapPatches
from planners.grid import GridMap
from planners.map_check import (
    AGREES,
    DIFFERS,
    MapCheck,
    MapCheckParams,
    check_map,
    fleet_verdict,
)
from planners.map_match import MatchParams

log = logging.getLogger("coordinator")

# wall seconds between looks at the sim clock
POLL_S = 0.2


def map_check_params(cfg: FleetConfig) -> MapCheckParams:
    """The matcher as the exploring coordinator merges with it: the SLAM map's wall width and
    thresholds, the acceptance test's defaults."""
    slam = cfg.slam
    return MapCheckParams(
        MatchParams(
            sigma=slam.match_sigma,
            occupied_threshold=slam.occupied_threshold,
            free_threshold=slam.free_threshold,
        )
    )


class MapWatch(Part):
    """The robots' maps against the stored map ``stored`` read from ``source``: a part of the
    coordinator on a stored map (wired to it by :meth:`wire`, its thread started with the
    coordinator's main loop)."""

    coordinator: Host
    changes: MapChanges  # set by wire, with the coordinator

    def __init__(self, bus: Bus, stored: GridMap, source: Path, cfg: FleetConfig) -> None:
        self.bus = bus
        self.stored = stored
        self.source = source
        self.cfg = cfg
        self.params = map_check_params(cfg)
        self.every_s = cfg.coordinator.map_check_every_s
        self.limits = (logit(cfg.slam.p_min), logit(cfg.slam.p_max))
        self.maps = RobotMaps()
        self.checks: dict[str, MapCheck] = {}
        # why the map was refused (None while it is not)
        self.refused: str | None = None
        self._lock = threading.Lock()
        self._looked_at = -float("inf")
        self._thread = threading.Thread(target=self._run, name="map-watch", daemon=True)

    def wire(self, host: Host) -> None:
        """The coordinator it checks for (and stops), and the watch for furniture moved since
        the map was made, which it keeps true after the check."""
        self.coordinator = host
        self.robots = host.expected
        self.changes = MapChanges(host, self.stored, map_change_params(self.cfg.coordinator))

    def serve(self) -> None:
        self.bus.subscribe(self.bus.keys.all_robots("map"), MapPatches, self._on_map)

    def start(self) -> None:
        self._thread.start()

    def refusal(self) -> str | None:
        return self.refused

    def _on_map(self, key: str, msg: MapPatches) -> None:
        c = self.coordinator
        rid = c.keys.robot_of(key)
        with c.lock:
            if c.implausible(key, rid, msg.stamp):
                return
        with self._lock:
            self.maps.hear(rid, msg)

    def _run(self) -> None:
        if self._check_map():
            self._watch_changes(self.changes)

    def _due(self) -> bool:
        """Wait until ``every_s`` sim seconds have passed since the last look (False once the
        coordinator stops); fetch the whole maps of robots whose patches had a gap."""
        stop = self.coordinator.stop
        while not stop.wait(POLL_S):
            clock = self.coordinator.journal.clock
            if clock - self._looked_at >= self.every_s:
                self._looked_at = clock
                fetch_whole_maps(self.bus, self.maps, self._lock)
                return True
        return False

    def _check_map(self) -> bool:
        """Check the map until the fleet's verdict; whether it was accepted."""
        while self._due():
            verdict = self.check()
            if verdict == AGREES:
                self._tell(
                    "map checked",
                    f"{self.source}: the robots' maps agree with it: {self._summary()}",
                )
                return True
            if verdict == DIFFERS:
                self.refused = (
                    f"{self.source}: the robots' scans do not match this stored map (another "
                    f"building, or not in the world's frame); stopped instead of driving on it: "
                    + self._summary()
                )
                self._tell("wrong map", self.refused)
                log.error("%s", self.refused)
                self.coordinator.stop.set()
                return False
        return False

    def _watch_changes(self, changes: MapChanges) -> None:
        """Compare the robots' maps with the stored map as changed so far, until the
        coordinator stops (:mod:`fleet.coordinator.map_changes`)."""
        while self._due():
            with self._lock:
                maps = self.maps.log_odds(self.limits)
            for change in changes.look(maps, self.limits):
                log.info("map changed: %s", change.describe())

    def check(self) -> str:
        """Judge each robot's map not yet judged; the fleet's verdict
        (``planners.map_check.fleet_verdict``)."""
        judged = {rid for rid, c in self.checks.items() if c.verdict in (AGREES, DIFFERS)}
        with self._lock:
            maps = self.maps.log_odds(self.limits, set(self.maps.cells) - judged)
        m = self.params.match
        for rid, lo in sorted(maps.items()):
            seen = lo.to_gridmap(m.occupied_threshold, m.free_threshold)
            self.checks[rid] = check_map(seen, self.stored, self.params)
            log.info("map check %s: %s", rid, self.checks[rid].reason)
        return fleet_verdict(self.checks.values(), self.robots)

    def _summary(self) -> str:
        return "; ".join(f"{rid} {c.verdict}: {c.reason}" for rid, c in sorted(self.checks.items()))

    def _tell(self, kind: str, detail: str) -> None:
        c = self.coordinator
        with c.lock:
            c.journal.event(kind, "", "", detail)
