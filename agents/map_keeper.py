"""What the robot shares and keeps of its SLAM map: the agent shell's map side.

The map's changed tiles go out at most ``agent.map_hz`` times per sim second on
``robot/<id>/map`` (a gap in their ``seq`` tells a receiver to fetch the whole map, served by
query on the same key), marked ``own_frame`` while the robot, started with no known pose, is
not yet placed on the fleet's map (:mod:`agents.placing`). With a state directory, the map and
pose are saved every ``agent.state_save_s`` and the pose alone every ``agent.pose_save_s``
(:mod:`agents.slam.persistence`), so a respawned robot finds itself in its old map, first near
its last pose.
"""

from __future__ import annotations

import logging
from pathlib import Path

from agents.pose_source import PoseSource
from agents.slam.persistence import save_pose, save_state
from agents.slam.slam_map import MapUpdate, PatchTracker, SlamMap
from fleet.bus import Bus
from fleet.params import FleetConfig
from fleet.protocol import MapPatches

log = logging.getLogger("agent")


class MapKeeper:
    """The map of one robot's pose source, published and saved (``state_dir`` None: not)."""

    def __init__(self, bus: Bus, rid: str, cfg: FleetConfig, state_dir: Path | None) -> None:
        self.bus = bus
        self.rid = rid
        self.cfg = cfg
        self.state_dir = state_dir
        # the map last published, which the market prices travel on until it has the floor plan
        self.snapshot: SlamMap | None = None
        self._seq = 0
        # whether the map is still in the robot's own frame (see agents.placing)
        self.own_frame = False
        self._patches = PatchTracker(cfg.slam.map_tile, cfg.slam.patch_tolerance)
        self._last_map = -1e9
        self._last_save = -1e9
        self._last_pose_save = -1e9

    def publish(self, stamp: float, source: PoseSource) -> None:
        """Publish the map's changed tiles, at most ``agent.map_hz`` times per sim second, and
        save the map and pose when due."""
        if stamp - self._last_map < 1.0 / self.cfg.agent.map_hz:
            return
        snapshot = source.occupancy()
        if snapshot is None:
            return
        self._last_map = stamp
        self.snapshot = snapshot
        if source.own_frame != self.own_frame:
            # placed: the map starts afresh in the fleet's frame, sent whole
            self.own_frame = source.own_frame
            self._patches = PatchTracker(self.cfg.slam.map_tile, self.cfg.slam.patch_tolerance)
        # a map in its own frame would be taken, after a respawn, for one in the fleet's
        if (
            self.state_dir is not None
            and not self.own_frame
            and stamp - self._last_save >= self.cfg.agent.state_save_s
        ):
            self._last_save = stamp
            try:
                save_state(self.state_dir, snapshot, source.pose(), stamp)
            except OSError as e:
                log.warning(
                    "%s: could not save its map and pose to %s: %s", self.rid, self.state_dir, e
                )
        update = self._patches.update(snapshot)
        if update.full or update.patches:
            self._seq += 1
            msg = map_message(stamp, self._seq, self.cfg.slam.map_tile, update, self.own_frame)
            self.bus.publish(self.bus.keys.robot(self.rid, "map"), msg)

    def whole(self, stamp: float) -> MapPatches:
        """The whole current map, for whoever joins late or noticed a gap in ``seq``."""
        snapshot = self.snapshot
        if snapshot is None:
            raise LookupError(f"{self.rid} has no map yet")
        update = PatchTracker(self.cfg.slam.map_tile, 0).update(snapshot)
        return map_message(stamp, self._seq, self.cfg.slam.map_tile, update, self.own_frame)

    def save_pose(self, stamp: float, source: PoseSource) -> None:
        """With a state directory, write the pose every ``agent.pose_save_s`` (sim time) once the
        robot knows where it is, so a respawn searches a small window around it."""
        if (
            self.state_dir is None
            or not source.localized
            or stamp - self._last_pose_save < self.cfg.agent.pose_save_s
        ):
            return
        self._last_pose_save = stamp
        try:
            save_pose(self.state_dir, source.pose(), stamp)
        except OSError as e:
            log.warning("%s: could not save its pose to %s: %s", self.rid, self.state_dir, e)


def map_message(
    stamp: float, seq: int, tile: int, update: MapUpdate, own_frame: bool = False
) -> MapPatches:
    return MapPatches.pack(
        stamp,
        seq,
        update.full,
        update.shape,
        update.resolution,
        update.origin,
        tile,
        [(p.row, p.col, p.data) for p in update.patches],
        own_frame,
    )
