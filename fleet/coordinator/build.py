"""The coordinator a configuration asks for: one :class:`fleet.coordinator.service.Coordinator`
with the parts (:mod:`fleet.coordinator.parts`) its features need, in any combination:

- batteries (``robot.battery.enabled``): :class:`fleet.coordinator.charging_part.ChargingPart`,
  on the world's docks;
- exploring (``coordinator --explore DIR``): :class:`fleet.coordinator.explore_part.
  ExplorePart`, planning on the robots' merged map instead of a floor plan;
- a stored map (``coordinator --map MAP.yaml``): :class:`fleet.coordinator.map_watch.MapWatch`,
  its check against the robots' maps and its changes.
"""

from __future__ import annotations

from pathlib import Path

from fleet.bus import Bus
from fleet.coordinator.charging import Pose
from fleet.coordinator.charging_part import ChargingPart
from fleet.coordinator.explore_part import ExplorePart
from fleet.coordinator.exploring import Explorer, MapPlanner
from fleet.coordinator.map_watch import MapWatch
from fleet.coordinator.parts import Part
from fleet.coordinator.planning import TaskPlanner
from fleet.coordinator.service import Coordinator
from fleet.coordinator.store import JobStore
from fleet.coordinator.transits import TransitPlanner
from fleet.params import FleetConfig
from fleet.plausible import Bounds
from planners.grid import GridMap


def build_coordinator(
    bus: Bus,
    cfg: FleetConfig,
    robots: int,
    store: JobStore | None,
    *,
    bounds: Bounds,
    planner: TaskPlanner | None = None,
    transits: TransitPlanner | None = None,
    explore: Path | None = None,
    docks: tuple[Pose, ...] = (),
    stored_map: tuple[GridMap, Path] | None = None,
) -> Coordinator:
    """The coordinator waiting for ``robots``, with the parts ``cfg`` and the options ask for:
    with ``explore`` (the directory the merged map goes to) it plans on the robots' merged map
    (``planner`` and ``transits`` unused), else on ``planner``'s floor plan; with
    ``robot.battery.enabled`` its robots charge at ``docks``; with ``stored_map`` (the map the
    floor plan is, and its file) it checks the map against the robots' own. ValueError for a
    combination that cannot run."""
    parts: list[Part] = []
    if explore is not None:
        explorer = Explorer(cfg, MapPlanner(cfg), explore)
        planner, transits = explorer.planner, None
        parts.append(ExplorePart(explorer))
    if planner is None:
        raise ValueError("a coordinator that does not explore plans on a floor plan")
    if cfg.robot.battery.enabled:
        if not docks:
            raise ValueError("robot.battery is on, but the world has no dock (dock: or docks:)")
        parts.append(ChargingPart(cfg.robot.battery, docks))
    if stored_map is not None:
        parts.append(MapWatch(bus, *stored_map, cfg))
    return Coordinator(
        bus, planner, robots, cfg.coordinator, store, transits, bounds=bounds, parts=parts
    )
