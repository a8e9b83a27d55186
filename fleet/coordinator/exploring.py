"""Exploring an unknown home: the robots' maps merged, their frontiers sold as tasks.

The coordinator of an exploring fleet has no floor plan: it knows only what the robots report.
Each robot's SLAM map comes as changed tiles (``robot/<id>/map``, :class:`RobotMaps` keeps a
copy of each; a gap in ``seq`` has the whole map fetched by query). Every
``coordinator.explore_every_s`` sim seconds :meth:`Explorer.update`:

1. merges the maps into one grid in the common frame (``planners.map_merge.merge_maps``, Birk
   and Carpin 2006). A robot's SLAM starts at its known start pose, so its map frame is the
   common frame (the prior is the identity, at every update); each map is then matched against
   the merge of those before it (``planners.map_match.refine_transforms``, Olson 2009) and
   moved only where the match is confident, which takes out the drift between the robots' maps.
   A map still in its robot's own frame (the robot started with no known pose) is left out and
   placed on the merge instead (:meth:`Explorer.place`, ``planners.map_match.place_map``);
2. extracts the merged map's frontiers a robot can reach (``planners.frontiers.find_frontiers``,
   Yamauchi 1997) with their expected information gain (Burgard et al. 2005);
3. makes each new frontier a task (``planners.frontier_tasks``: drive to its goal), and takes
   off the market every task whose frontier vanished (state ``gone``; a robot driving to it
   stops and bids again), one no robot could reach included.

Plans are A* on the merged map (:class:`MapPlanner`: robot centres on known floor clear of
walls by the robot's radius). The market sells a frontier's task to one idle robot at a time;
its call is worth the discounted information gain (``planners.frontier_tasks.call_values``),
and each robot's bid takes that off its travel, which it prices on its own map. Exploring is
over when no task is open or assigned and an update, with every robot once placed on the merged
map's floor, finds no new frontier. The merged map is written as a ROS map_server pair
(``map.yaml``, ``map.pgm``) after every update.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from PIL import Image

from fleet.bus import Bus
from fleet.coordinator.job import (
    ASSIGNED,
    FRONTIER_PREFIX,
    GONE,
    OPEN,
    REPLACED,
    UNREACHABLE,
    Job,
)
from fleet.coordinator.planning import TaskPlanner
from fleet.floor_map import apply_patches
from fleet.params import FleetConfig
from fleet.protocol import MapPatches, Request
from planners.auction import Lot, Task, task_lot
from planners.frontier_tasks import call_values, goal_task, new_frontiers, still_there
from planners.frontiers import Frontier, centre_reachable, find_frontiers, placed
from planners.grid import GridMap
from planners.map_match import MapMatch, MatchParams, place_map, refine_transforms
from planners.map_merge import LogOddsMap, Transform2D, merge_maps

log = logging.getLogger("coordinator")

MAP_YAML = "map.yaml"
MAP_PGM = "map.pgm"
# ROS map_saver's trinary pixels and thresholds
PGM_FREE, PGM_OCCUPIED, PGM_UNKNOWN = 254, 0, 205
FREE_THRESH, OCCUPIED_THRESH = 0.196, 0.65
# wall seconds a robot's whole map is waited for
WHOLE_MAP_TIMEOUT_S = 2.0


class RobotMaps:
    """Each robot's SLAM map as its patches told it (int8 OccupancyGrid values)."""

    def __init__(self) -> None:
        self.cells: dict[str, np.ndarray] = {}
        self.geometry: dict[str, tuple[float, tuple[float, float]]] = {}
        self.seq: dict[str, int] = {}
        # robots whose whole map must be fetched: a gap in their patches' seq
        self.missing: set[str] = set()
        # robots whose map is in their own frame: started with no known pose, not yet placed
        self.own_frame: set[str] = set()

    def hear(self, rid: str, msg: MapPatches) -> None:
        """Write ``msg``'s tiles into ``rid``'s copy; a gap in ``seq`` (or patches before any
        whole map, or patches in another frame than the copy's) marks the robot's whole map as
        missing."""
        switched = msg.own_frame != (rid in self.own_frame)
        if not msg.full and (switched or msg.seq != self.seq.get(rid, -2) + 1):
            self.missing.add(rid)
            if switched:
                return
        try:
            cells = apply_patches(self.cells.get(rid), msg)
        except ValueError:
            return
        self.cells[rid] = cells
        self.geometry[rid] = (msg.resolution, (msg.origin_x, msg.origin_y))
        self.seq[rid] = msg.seq
        if msg.own_frame:
            self.own_frame.add(rid)
        else:
            self.own_frame.discard(rid)
        if msg.full:
            self.missing.discard(rid)

    def log_odds(
        self, limits: tuple[float, float], robots: Iterable[str] | None = None
    ) -> dict[str, LogOddsMap]:
        """Each robot's map (of ``robots`` only, when given) as log-odds, by robot id."""
        wanted = None if robots is None else set(robots)
        return {
            rid: LogOddsMap.from_ros(cells, *self.geometry[rid], limits)
            for rid, cells in sorted(self.cells.items())
            if wanted is None or rid in wanted
        }


def fetch_whole_maps(bus: Bus, maps: RobotMaps, lock: AbstractContextManager) -> None:
    """Ask each robot whose patches had a gap for its whole map, and write it into ``maps``
    (guarded by ``lock``, which is not held while a robot answers). A caller runs this on a
    thread of its own: each query may wait :data:`WHOLE_MAP_TIMEOUT_S`."""
    with lock:
        missing = sorted(maps.missing)
    for rid in missing:
        try:
            msg = bus.request(
                bus.keys.robot(rid, "map"), Request("coordinator"), MapPatches, WHOLE_MAP_TIMEOUT_S
            )
        except (TimeoutError, RuntimeError) as e:
            log.info("%s: no whole map yet (%s)", rid, e)
            continue
        with lock:
            maps.hear(rid, msg)


class MapPlanner(TaskPlanner):
    """Plans on the fleet's merged map as it grows (no floor plan, no tour: no tasks of its
    own)."""

    def __init__(self, cfg: FleetConfig) -> None:
        self._configure(cfg)
        # robot centres a radius off the merged map's faces, with no wall_clearance on top: a
        # map draws each face up to a cell in front of the true one (a cell a face crosses is
        # occupied whole), and one cell more would close a passage a robot fits through
        self.centre_clearance = self.robot.radius
        self.use_floor(
            GridMap(np.zeros((1, 1), bool), np.ones((1, 1), bool), cfg.slam.resolution, (0, 0)),
            np.zeros((1, 1), dtype=bool),
        )

    def tasks(self) -> tuple[Task, ...]:
        return ()


@dataclass(frozen=True)
class Change:
    """What an update did: the tasks it made, and those it took off as gone (with the robot
    that held each, or None); the merged map it made; where it placed each map still in its
    robot's own frame (``placements``, confident or not)."""

    added: tuple[Task, ...]
    gone: tuple[tuple[str, str | None], ...]
    frontiers: int
    known_m2: float
    grid: GridMap
    placements: dict[str, MapMatch] = field(default_factory=dict)


@dataclass(frozen=True)
class Snapshot:
    """What an update reads of the robots' maps and the job: taken with the lock held, and
    cheap (:meth:`RobotMaps.hear` replaces a robot's cells whole, never writes into them)."""

    cells: dict[str, np.ndarray]
    geometry: dict[str, tuple[float, tuple[float, float]]]
    positions: dict[str, tuple[float, float]]
    own_frame: frozenset[str] = frozenset()


@dataclass(frozen=True)
class Survey:
    """The merged map, its frontiers, the floor robot centres reach on it and each robot's
    position in its frame, and which robots' maps it holds: the costly part of an update,
    made without the lock."""

    grid: GridMap
    frontiers: tuple[Frontier, ...]
    reach: np.ndarray
    positions: dict[str, np.ndarray]
    mapped: frozenset[str]
    placements: dict[str, MapMatch] = field(default_factory=dict)


class Explorer:
    """The merged map, its frontiers, and the frontier tasks of the job."""

    def __init__(self, cfg: FleetConfig, planner: MapPlanner, out_dir: Path | None) -> None:
        slam = cfg.slam
        self.params = cfg.coordinator
        self.planner = planner
        self.out_dir = out_dir
        self.limits = (logit(slam.p_min), logit(slam.p_max))
        self.thresholds = (slam.occupied_threshold, slam.free_threshold)
        self.match = MatchParams(
            sigma=slam.match_sigma,
            occupied_threshold=slam.occupied_threshold,
            free_threshold=slam.free_threshold,
        )
        self.sensor_range = cfg.lidar.range_max
        self.clearance = planner.centre_clearance
        self.maps = RobotMaps()
        self.seq = 0
        # the robots that have stood on the merged map's floor
        self.placed: set[str] = set()
        # the last update found no new frontier while no task was open or assigned
        self.exhausted = False

    def update(self, job: Job) -> Change | None:
        """:meth:`snapshot`, :meth:`survey` and :meth:`apply` at once; None before any robot
        has sent its map."""
        survey = self.survey(self.snapshot(job))
        return None if survey is None else self.apply(job, survey)

    def snapshot(self, job: Job) -> Snapshot:
        """The maps and the robots' positions as they are now (call with the lock held)."""
        return Snapshot(
            dict(self.maps.cells),
            dict(self.maps.geometry),
            {rid: r.xy for rid, r in sorted(job.robots.items()) if r.xy is not None},
            frozenset(self.maps.own_frame),
        )

    def survey(self, snap: Snapshot) -> Survey | None:
        """Merge the maps and extract the reachable frontiers (no lock needed: on a large home
        this takes a second or more, and a coordinator deaf for that long would take its robots
        for lost); writes the merged map, and places the maps of robots that started with no
        known pose on it (:meth:`place`). None before any robot has sent a map in the fleet's
        frame."""
        every = {
            rid: LogOddsMap.from_ros(cells, *snap.geometry[rid], self.limits)
            for rid, cells in sorted(snap.cells.items())
        }
        maps = {rid: m for rid, m in every.items() if rid not in snap.own_frame}
        if not maps:
            return None
        ids = list(maps)
        # the known start poses, every time: a wrong match then costs one update, never the
        # prior of every later one
        priors = [Transform2D.identity()] * len(ids)
        matches = refine_transforms(list(maps.values()), priors, self.limits, self.match)
        transforms = {rid: m.transform for rid, m in zip(ids, matches, strict=True)}
        merged = merge_maps(list(maps.values()), [m.transform for m in matches], self.limits)
        grid = merged.to_gridmap(*self.thresholds)
        positions = {
            rid: transforms.get(rid, Transform2D.identity()).apply(np.array(xy))
            for rid, xy in snap.positions.items()
        }
        robots = np.array(list(positions.values()), dtype=float).reshape(-1, 2)
        reach = centre_reachable(grid, robots, self.clearance)
        frontiers = tuple(
            f
            for f in find_frontiers(grid, robots, self.clearance, self.sensor_range, reach)
            if f.information_gain >= self.params.explore_min_gain_m2
        )
        if self.out_dir is not None:
            write_ros_map(self.out_dir, grid)
        unplaced = {rid: m for rid, m in every.items() if rid in snap.own_frame}
        placements = {rid: self.place(m, grid) for rid, m in unplaced.items()}
        return Survey(grid, frontiers, reach, positions, frozenset(maps), placements)

    def place(self, own: LogOddsMap, merged: GridMap) -> MapMatch:
        """Where a map in a robot's own frame lies on the merged map: a search over every
        rotation and translation (``planners.map_match.place_map``), confident only when the
        maps overlap enough and agree, with no near rival (Birk and Carpin 2006)."""
        return place_map(own.to_gridmap(*self.thresholds), merged, self.match)

    def apply(self, job: Job, survey: Survey) -> Change:
        """Add the survey's new frontiers to ``job`` as tasks and drop the tasks whose frontier
        vanished (call with the lock held)."""
        grid = survey.grid
        self.planner.use_floor(grid, survey.reach)
        gone = self._drop_vanished(job, list(survey.frontiers), grid)
        taken = np.array(
            [rec.task.entry for rec in job.tasks.values() if rec.state not in (GONE, REPLACED)]
        ).reshape(-1, 2)
        gone_at = np.array(
            [rec.task.entry for rec in job.tasks.values() if rec.state == GONE]
        ).reshape(-1, 2)
        added = []
        for f in new_frontiers(list(survey.frontiers), taken, self.params.explore_match_m, gone_at):
            self.seq += 1
            task = goal_task(f"{FRONTIER_PREFIX}{self.seq:03d}", f, self.params.explore_step_m)
            job.add_tasks((task,))
            added.append(task)
        busy = any(rec.state in (OPEN, ASSIGNED) for rec in job.tasks.values())
        # over only once every robot's map is in and each robot stands on the merged map's
        # floor: a robot that has not scanned yet, or whose surroundings are still unknown,
        # reaches no frontier, and that is no proof that none is left
        self.exhausted = self._everyone_placed(job, survey) and not busy
        known = float((grid.free | grid.occupied).sum()) * grid.resolution**2
        return Change(
            tuple(added), tuple(gone), len(survey.frontiers), known, grid, survey.placements
        )

    def _everyone_placed(self, job: Job, survey: Survey) -> bool:
        """Whether every robot in the market has sent its map and has stood on the merged
        map's floor at some update (once placed, a robot wedged off it later holds nothing
        up)."""
        market = job.market()
        new = [rid for rid in market if rid not in self.placed and rid in survey.positions]
        if new:
            xy = np.array([survey.positions[rid] for rid in new])
            ok = placed(survey.grid, xy, self.clearance)
            self.placed.update(rid for rid, yes in zip(new, ok, strict=True) if yes)
        return set(market) <= survey.mapped & self.placed

    def _drop_vanished(
        self, job: Job, frontiers: list[Frontier], grid: GridMap
    ) -> list[tuple[str, str | None]]:
        # an unreachable frontier the robots mapped another way is no work left out
        alive = [rec for rec in job.tasks.values() if rec.state in (OPEN, ASSIGNED, UNREACHABLE)]
        if not alive:
            return []
        goals = np.array([rec.task.entry for rec in alive])
        there = still_there(goals, frontiers, grid, self.params.explore_match_m)
        return [
            (rec.task.id, job.drop(rec.task.id))
            for rec, ok in zip(alive, there, strict=True)
            if not ok
        ]

    def finished(self, job: Job) -> bool:
        """No task open or assigned, and the last update, with every robot's map in and floor
        on the merged map, found no new frontier."""
        return self.exhausted and not any(
            rec.state in (OPEN, ASSIGNED) for rec in job.tasks.values()
        )

    def lots(self, job: Job) -> dict[str, Lot]:
        """The open tasks for sale, each worth its discounted information gain
        (``planners.frontier_tasks.call_values``) given the goals robots are headed to."""
        open_recs = job.open_tasks()
        if not open_recs:
            return {}
        goals = np.array([rec.task.entry for rec in open_recs])
        headed = np.array(
            [rec.task.entry for rec in job.tasks.values() if rec.state == ASSIGNED]
        ).reshape(-1, 2)
        gains = np.array([rec.task.area_m2 for rec in open_recs])
        values = call_values(
            gains, goals, headed, self.sensor_range, self.params.explore_gain_s_per_m2
        )
        out = {}
        for rec, value in zip(open_recs, values, strict=True):
            lot = task_lot(rec.task)
            out[lot.id] = Lot(lot.id, lot.tasks, lot.entry, lot.exit, 0.0, lot.area_m2, value)
        return out


def write_ros_map(out_dir: Path, grid: GridMap) -> None:
    """``grid`` as a ROS map_server pair in ``out_dir`` (trinary PGM as map_saver writes it:
    free 254, occupied 0, unknown 205; image row 0 is the highest y), written through
    temporary files so a reader never sees half a map."""
    pixels = np.full(grid.shape, PGM_UNKNOWN, dtype=np.uint8)
    pixels[grid.free] = PGM_FREE
    pixels[grid.occupied] = PGM_OCCUPIED
    out_dir.mkdir(parents=True, exist_ok=True)
    tmp = out_dir / (MAP_PGM + ".tmp")
    Image.fromarray(np.flipud(pixels)).save(tmp, format="PPM")
    tmp.replace(out_dir / MAP_PGM)
    yaml = (
        f"image: {MAP_PGM}\nresolution: {grid.resolution}\n"
        f"origin: [{grid.origin[0]}, {grid.origin[1]}, 0.0]\nnegate: 0\n"
        f"occupied_thresh: {OCCUPIED_THRESH}\nfree_thresh: {FREE_THRESH}\nmode: trinary\n"
    )
    tmp = out_dir / (MAP_YAML + ".tmp")
    tmp.write_text(yaml)
    tmp.replace(out_dir / MAP_YAML)


def logit(p: float) -> float:
    """log(p / (1 − p)): a probability as log-odds."""
    return float(np.log(p / (1.0 - p)))
