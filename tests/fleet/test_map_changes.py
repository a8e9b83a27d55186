"""The coordinator's side of furniture moved since the stored map was made, without a bus: a
change found on the robots' maps is told, put on the planning map, and the task whose lane
runs through the new furniture is taken back from its owner and replaced by what can be
driven round it, what the owner swept staying swept; a lane clear of it is left alone, and a
change is told once. Floor that furniture taken away frees goes on the planning map, and no
task is made for it."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from map_pieces import L_FREE, L_OCC, RES
from robots import ROBOT

from fleet.config import resolve_world
from fleet.coordinator.awards import Awards
from fleet.coordinator.dispatcher import Dispatcher
from fleet.coordinator.job import ASSIGNED, BLOCKED, OPEN, REPLACED, Job
from fleet.coordinator.journal import Journal
from fleet.coordinator.map_changes import MAP_CHANGED, MapChanges
from fleet.coordinator.market import Market
from fleet.coordinator.planning import TaskPlanner
from fleet.coordinator.service import plan_tour
from fleet.params import CoordinatorParams, load_fleet_config
from fleet.protocol import FleetEvent, Keys, Message, Plan
from fleet.world import load_world
from planners.auction import Task
from planners.bodies import Rerouted
from planners.coverage.metrics import swath
from planners.coverage.params import CoverageParams
from planners.grid import GridMap
from planners.map_change import ADDED, REMOVED, MapChange, MapChangeParams
from planners.map_merge import LogOddsMap
from planners.polyline import densify

KEYS = Keys("test")
CFG = load_fleet_config()
# a chest moved onto the small world's open floor, west of its table
CHEST = (1.05, 2.0, 1.55, 2.4)


def _lane(tid: str, y: float, x0: float = 0.4, x1: float = 3.6) -> Task:
    path = np.column_stack([np.linspace(x0, x1, 9), np.full(9, y)])
    return Task(tid, path, 0.3 * (x1 - x0), 2.0 * (x1 - x0), (1,))


class Stand:
    """The coordinator's parts a map change touches, publishing into a list."""

    def __init__(self) -> None:
        self.planner = TaskPlanner(load_world(resolve_world("small"), CFG.robot.radius), CFG)
        self.job = Job(CoverageParams(), ROBOT, 0.0)
        self.sent: list[tuple[str, Message]] = []
        self.lock = threading.RLock()
        self.journal = Journal(self.job, None, KEYS, self.publish)
        awards = Awards(self.journal, KEYS, self.publish)
        params = CoordinatorParams()
        self.dispatcher = Dispatcher(self.journal, self.planner, None, params, KEYS, self.publish)
        self.market = Market(
            self.journal, awards, self.dispatcher, self.lock, threading.Event(), threading.Event()
        )
        self.stored = self.planner.grid

    def publish(self, key: str, msg: Message, _control: bool) -> None:
        self.sent.append((key, msg))

    def events(self, kind: str) -> list[FleetEvent]:
        return [m for _, m in self.sent if isinstance(m, FleetEvent) and m.kind == kind]


def chest_faces(sides: str = "sw") -> np.ndarray:
    """Cell centres (5 cm) of the chest's faces a robot south-west of it sees."""
    x0, y0, x1, y1 = CHEST
    xs = np.arange(x0 + RES / 2, x1, RES)
    ys = np.arange(y0 + RES / 2, y1, RES)
    faces = []
    if "s" in sides:
        faces.append(np.column_stack([xs, np.full(len(xs), y0 + RES / 2)]))
    if "w" in sides:
        faces.append(np.column_stack([np.full(len(ys), x0 + RES / 2), ys]))
    if "n" in sides:
        faces.append(np.column_stack([xs, np.full(len(xs), y1 - RES / 2)]))
    if "e" in sides:
        faces.append(np.column_stack([np.full(len(ys), x1 - RES / 2), ys]))
    return np.unique(np.vstack(faces).round(4), axis=0)


@pytest.fixture
def stand() -> Stand:
    s = Stand()
    s.job.add_tasks((_lane("t00", 2.2), _lane("t01", 0.9)))
    for tid, rid in (("t00", "robot-0"), ("t01", "robot-1")):
        s.job.robot(rid).ready = True
        s.job.award(tid, rid, False)
        s.dispatcher.plans[rid] = Plan(0.0, 1, tid, s.job.tasks[tid].task.path, 0)
    s.job.robots["robot-0"].xy = (0.8, 2.2)
    s.job.robots["robot-1"].xy = (0.6, 0.9)
    # robot-0 has swept its lane's first piece
    s.job.progress("robot-0", "t00", np.eye(8, dtype=bool)[0])
    return s


def _far_from_chest(path: np.ndarray, margin: float) -> bool:
    pts = densify(path, 0.01)
    x0, y0, x1, y1 = CHEST
    dx = np.maximum(np.maximum(x0 - pts[:, 0], pts[:, 0] - x1), 0.0)
    dy = np.maximum(np.maximum(y0 - pts[:, 1], pts[:, 1] - y1), 0.0)
    return bool(np.hypot(dx, dy).min() >= margin)


def test_a_lane_through_new_furniture_is_replanned_round_it(stand: Stand) -> None:
    changes = MapChanges(stand, stand.stored, MapChangeParams())  # type: ignore[arg-type]
    changes.take(MapChange(ADDED, chest_faces("swne"), RES))
    told = stand.events(MAP_CHANGED)
    assert len(told) == 1 and "0.50 × 0.40 m at (1.30, 2.20)" in told[0].detail, told
    job = stand.job
    # t00 runs through the chest: taken back from robot-0, its plan dropped
    assert job.tasks["t00"].state == REPLACED and "robot-0" not in stand.dispatcher.plans
    assert stand.events("withdrawn")[0].task == "t00"
    # what robot-0 swept stays swept: its remainder starts where it stopped
    rest = job.tasks["t00.1"]
    assert rest.state == REPLACED and np.allclose(rest.task.path[0], [0.8, 2.2])
    parts = [r for r in job.tasks.values() if r.parent == "t00.1"]
    assert parts and all(r.state == OPEN for r in parts), [(r.task.id, r.state) for r in parts]
    # nothing of what is sold again runs into the chest: robot centres keep clear of it
    clear = ROBOT.radius + CFG.coordinator.wall_clearance - 0.03
    assert all(_far_from_chest(r.task.path, clear) for r in parts)
    # the floor under the chest is no work left out
    assert not [r for r in job.tasks.values() if r.state == BLOCKED]
    # t01 lies clear of the chest: robot-1 keeps it
    assert job.tasks["t01"].state == ASSIGNED and "robot-1" in stand.dispatcher.plans
    # the planning map has the chest, and transits go round it
    g = stand.planner.grid
    rc = g.world_to_cell(np.array([[1.3, 2.2], [1.06, 2.01], [1.54, 2.39]]))
    assert g.occupied[rc[:, 0], rc[:, 1]].all()
    way = stand.planner.transit.path(np.array([0.6, 2.2]), np.array([1.85, 2.2]))
    assert _far_from_chest(way, clear)
    assert stand.market.need_auction


def test_the_robots_maps_show_the_change_once(stand: Stand) -> None:
    stored = stand.stored
    # robot-0's SLAM map, 5 cm: the floor as the stored map has it, and the chest's faces
    world = load_world(resolve_world("small"), CFG.robot.radius).grid(RES)
    lo = np.where(world.occupied, L_OCC, L_FREE).astype(np.float32)
    # what lies behind the faces seen is not seen
    inside = world.world_to_cell(chest_faces("swne"))
    lo[inside[:, 0].min() : inside[:, 0].max() + 1, inside[:, 1].min() : inside[:, 1].max() + 1] = 0
    chest = world.world_to_cell(chest_faces("sw"))
    lo[chest[:, 0], chest[:, 1]] = L_OCC
    seen = {"robot-0": LogOddsMap(lo, RES, world.origin)}
    limits = (L_FREE, L_OCC)
    changes = MapChanges(stand, stored, MapChangeParams())  # type: ignore[arg-type]
    found = changes.look(seen, limits)
    assert [c.kind for c in found] == [ADDED]
    x0, y0, x1, y1 = found[0].bounds
    assert np.allclose((x0, y0, x1, y1), CHEST, atol=0.03), found[0].describe()
    assert changes.look(seen, limits) == () and len(stand.events(MAP_CHANGED)) == 1
    # the two faces seen span the chest: all of it is planned round, its far corner too
    g = stand.planner.grid
    rc = g.world_to_cell(np.array([[1.3, 2.2], [1.53, 2.38]]))
    assert g.occupied[rc[:, 0], rc[:, 1]].all()
    assert "planned round as x 1.05–1.55, y 2.00–2.40" in stand.events(MAP_CHANGED)[0].detail
    assert isinstance(changes.stored, GridMap) and changes.stored is not stored


def test_the_far_face_seen_later_makes_the_piece_whole(stand: Stand) -> None:
    changes = MapChanges(stand, stand.stored, MapChangeParams())  # type: ignore[arg-type]
    changes.take(MapChange(ADDED, chest_faces("s"), RES))
    g = stand.planner.grid
    middle = g.world_to_cell(np.array([1.3, 2.2]))
    assert not g.occupied[middle[0], middle[1]]
    changes.take(MapChange(ADDED, chest_faces("n"), RES))
    g = stand.planner.grid
    assert g.occupied[middle[0], middle[1]] and len(changes.obstacles) == 1
    assert "planned round as x 1.05–1.55, y 2.00–2.40" in stand.events(MAP_CHANGED)[1].detail


# the small world's table, (xmin, ymin, xmax, ymax): taken away in the tests below
TABLE = (2.0, 1.3, 2.8, 1.9)


def table_cells(grid: GridMap) -> np.ndarray:
    """Cell centres of ``grid``'s obstacle cells that make the table (its rasterized footprint
    reaches a cell beyond the table's edges): the floor robots see free once it is gone."""
    x0, y0, x1, y1 = TABLE
    xy = grid.cell_to_world(np.argwhere(grid.occupied))
    near = (xy[:, 0] > x0 - 0.05) & (xy[:, 0] < x1 + 0.05)
    return xy[near & (xy[:, 1] > y0 - 0.05) & (xy[:, 1] < y1 + 0.05)]


def test_a_lane_through_new_furniture_is_rerouted_once(stand: Stand) -> None:
    calls: list[int] = []
    planner = stand.planner
    reroute = planner.reroute

    def counted(path: np.ndarray) -> Rerouted:
        calls.append(1)
        return reroute(path)

    planner.reroute = counted  # type: ignore[method-assign]
    MapChanges(stand, stand.stored, MapChangeParams()).take(  # type: ignore[arg-type]
        MapChange(ADDED, chest_faces("swne"), RES)
    )
    # t00 runs through the chest, t01 lies clear of it; t00's remainder too is rerouted
    assert stand.job.tasks["t00"].state == REPLACED
    assert len(calls) == 2, len(calls)


def test_before_the_tour_is_cut_freed_floor_is_left_to_the_tour() -> None:
    stand = Stand()
    changes = MapChanges(stand, stand.stored, MapChangeParams())  # type: ignore[arg-type]
    changes.take(MapChange(REMOVED, table_cells(stand.stored), stand.stored.resolution))
    g = stand.planner.grid
    middle = g.world_to_cell(np.array([2.4, 1.6]))
    assert g.free[middle[0], middle[1]] and not stand.job.tasks
    # the tour planned now sweeps where the table stood
    tour = stand.planner.tasks()
    swept = np.zeros(g.shape, dtype=bool)
    for t in tour:
        swept |= swath(g, t.path, CFG.robot.cleaning_width / 2)[0]
    assert swept[middle[0], middle[1]]


def test_a_change_found_while_the_tour_is_planned_waits_for_the_tasks() -> None:
    stand = Stand()
    changes = MapChanges(stand, stand.stored, MapChangeParams())  # type: ignore[arg-type]
    table = MapChange(REMOVED, table_cells(stand.stored), stand.stored.resolution)
    planner, plan = stand.planner, stand.planner.tasks
    floor = planner.grid
    taken = []

    def plan_and_look() -> tuple[Task, ...]:
        tour = plan()
        # the map watch's thread finds the table gone while the tour is planned
        taken.append(changes.take(table))
        return tour

    planner.tasks = plan_and_look  # type: ignore[method-assign]
    plan_tour(planner, stand.lock, stand.job.add_tasks)
    assert taken == [False] and planner.grid is floor and not planner.planning
    assert not stand.events(MAP_CHANGED) and stand.job.tasks
    # the next look, the tour cut: the change is taken
    tasks = set(stand.job.tasks)
    assert changes.take(table) and len(stand.events(MAP_CHANGED)) == 1
    assert planner.grid is not floor and set(stand.job.tasks) == tasks


def test_floor_a_table_taken_away_frees_is_on_the_map_and_in_no_task(stand: Stand) -> None:
    before, tasks = stand.planner.brushable.copy(), set(stand.job.tasks)
    changes = MapChanges(stand, stand.stored, MapChangeParams())  # type: ignore[arg-type]
    assert changes.take(MapChange(REMOVED, table_cells(stand.stored), stand.stored.resolution))
    assert len(stand.events(MAP_CHANGED)) == 1
    g = stand.planner.grid
    middle = g.world_to_cell(np.array([2.4, 1.6]))
    assert g.free[middle[0], middle[1]]
    # the brush reaches the table's floor now, and transits may cross it
    freed = stand.planner.brushable & ~before
    assert freed.sum() * g.resolution**2 > 0.48  # the table's 0.8 × 0.6 m and the band round it
    way = stand.planner.transit.path(np.array([2.4, 1.0]), np.array([2.4, 2.2]))
    assert np.allclose(way[:, 0], 2.4), way
    # no task sweeps it, nothing is taken back, nothing is sold
    assert set(stand.job.tasks) == tasks and not stand.market.need_auction
    assert stand.job.tasks["t00"].state == ASSIGNED and stand.job.tasks["t01"].state == ASSIGNED
