"""The coverage planner: rooms, their boustrophedon cells, sweep tasks, order, split, metrics."""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import networkx as nx
import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist

from planners.coverage.bcd import MonotoneCell, decompose
from planners.coverage.fill_in import fill_in_tasks
from planners.coverage.frame import RotatedFrame, dominant_direction, frame_for, resample
from planners.coverage.geodesic import PathCosts
from planners.coverage.lattice import room_lanes
from planners.coverage.metrics import CoverageMetrics, path_time, plan_metrics, swath
from planners.coverage.ordering import split_tour
from planners.coverage.params import CoverageParams
from planners.coverage.prune import Footprints, footprint, prune_driven, prune_tasks
from planners.coverage.rooms import segment_rooms, shared_borders
from planners.coverage.strips import return_strips
from planners.coverage.tasks import (
    SweepTask,
    cell_tasks,
    strip_task,
)
from planners.coverage.tour import (
    TaskEnds,
    end_points,
    insert_run,
    path_of,
    plan_tour,
    task_ends,
    tour_cost,
)
from planners.coverage.transit import Transit
from planners.grid import GridMap, cleanable, clearance, extend_labels, reachable
from planners.polyline import densify, without_repeats, without_straight_vertices
from planners.robot import RobotSpec

# A wall direction this close to a grid axis is taken as the axis: lanes then lie exactly
# between rows of cells, and the rasterized walls of an axis-aligned plan measure slightly off.
AXIS_SNAP = math.radians(1.0)
# fill-in passes change the tour and so its transits; this many rounds settle what they miss
FILL_IN_ROUNDS = 3
# a dead-end room's lanes turn across the usual axis only when its own tour gets this much
# shorter (the estimate leaves out the fill-in, which the other axis may need more of)
AXIS_MARGIN = 0.03
MISS_FACTOR = 2.0
# the fill-in goes on to clean this share of the floor fill_in_target leaves; the final
# pruning then trades that surplus back for the tasks that cost more driving per cell
FILL_IN_SURPLUS = 0.6


@dataclass(frozen=True, eq=False)
class CoveragePlan:
    """The result of :func:`plan_coverage`.

    ``paths[i]`` is robot i's (N, 2) waypoint path in world metres, beginning at its start.
    ``room_labels`` / ``cell_labels`` are grid-shaped int32 images (0 = not cleanable) of the
    rooms and of the boustrophedon cells; ``room_graph`` and ``cell_graph`` are their adjacency
    graphs (node attributes ``area_m2``, ``entry_points`` (K, 2) world, and ``room``/``angle``;
    room edges carry ``door`` (x, y) and ``width_m``). ``assignment`` maps every cell to the robot
    that sweeps the most of it (a large cell may be shared: see ``tasks``). ``unreachable`` marks
    the free cells no robot can clean (beyond the swath of every reachable centre, or cut off).
    """

    paths: tuple[np.ndarray, ...]
    starts: tuple[tuple[float, float], ...]
    room_labels: np.ndarray
    cell_labels: np.ndarray
    room_graph: nx.Graph
    cell_graph: nx.Graph
    assignment: dict[int, int]
    tasks: tuple[tuple[SweepTask, ...], ...]
    metrics: CoverageMetrics
    cleanable: np.ndarray
    unreachable: np.ndarray
    unreachable_area_m2: float
    plan_time_s: float
    params: CoverageParams


class PlanningError(ValueError):
    """The map or the starts do not allow a plan (the message says why)."""


def plan_coverage(
    grid: GridMap,
    starts: Sequence[tuple[float, float]],
    params: CoverageParams,
    robot: RobotSpec,
    *,
    wall_clearance: float,
) -> CoveragePlan:
    """Plan coverage by ``robot`` of all floor reachable from ``starts`` (one per robot, world
    metres), its centre kept ``wall_clearance`` more than its radius from obstacles.

    Steps: robot-centre cells (clearance ≥ radius + ``wall_clearance``) 4-connected to a start;
    rooms by distance-transform segmentation; per room the dominant wall direction, a frame
    rotated to it and the boustrophedon decomposition (Choset 2000) of the room in that frame;
    lanes on one lattice per room (``lattice.room_lanes``); in a dead-end room, lanes along
    either axis, with a return strip (``strips.return_strips``) on either lane-end side or none,
    whichever gives the shortest tour of the room alone from its door and back; sweep tasks per
    cell (its boustrophedon lanes, each cut into pieces); one tour over all tasks of a connected
    part of the floor (``tour.plan_tour``: task order, direction and variant by path-cost
    estimates between task ends, ``geodesic.PathCosts``); with ``params.fill_in``, targeted
    passes for the floor the sweeps miss (``fill_in.fill_in_tasks``) inserted into the tour
    where they cost least; for k robots the tour is cut into contiguous pieces balancing
    estimated time, each re-ordered from its robot's start; last, the tasks whose floor the rest
    of the driven path cleans anyway go, and the fill-in's surplus over
    ``params.fill_in_target`` is traded for the tasks that cost the most driving per cell
    (``prune.prune_driven``). Transits are straight when clear, A* on the inflated grid
    otherwise.
    """
    t0 = time.perf_counter()
    params.validate()
    robot.validate()
    floor = _floor(grid, starts, robot, wall_clearance)
    # one PathCosts for all stages: each stage's queries reuse the costs the earlier ones computed
    costs = PathCosts(grid, floor.reach)
    sweeps = _room_sweeps(grid, floor, costs, params, robot)
    transit = Transit(grid, floor.reach)
    tasks, pieces = _robot_tours(grid, floor, sweeps, costs, transit, params, robot)
    return _assemble(grid, floor, sweeps, tasks, pieces, transit, params, robot, wall_clearance, t0)


@dataclass(frozen=True, eq=False)
class _Floor:
    """The floor as the robots can use it: ``clear`` every cell's clearance (m), ``reach`` the
    robot-centre cells 4-connected to a start, ``clean`` the cells their swaths reach, ``comp``
    the connected parts of ``reach`` (labels); the starts as (k, 2) world points, their cells
    and the part each lies in (``robot_comp``)."""

    clear: np.ndarray
    reach: np.ndarray
    clean: np.ndarray
    comp: np.ndarray
    start_xy: np.ndarray
    start_cells: np.ndarray
    robot_comp: np.ndarray


def _floor(
    grid: GridMap, starts: Sequence[tuple[float, float]], robot: RobotSpec, wall_clearance: float
) -> _Floor:
    """The floor reachable from ``starts`` by a robot centre keeping ``robot.radius +
    wall_clearance`` from obstacles; a :class:`PlanningError` when there is none to plan on."""
    if not grid.free.any():
        raise PlanningError("the map has no free cell")
    if len(starts) == 0:
        raise PlanningError("no start given")
    clear = clearance(grid)
    centres = clear >= robot.radius + wall_clearance
    start_xy = np.array(starts, dtype=float).reshape(-1, 2)
    start_cells = grid.world_to_cell(start_xy)
    _check_starts(grid, start_xy, start_cells, centres, robot, wall_clearance)
    reach = reachable(centres, start_cells)
    comp, _ = ndimage.label(reach)
    return _Floor(
        clear=clear,
        reach=reach,
        clean=cleanable(grid, reach, robot.cleaning_width / 2),
        comp=comp,
        start_xy=start_xy,
        start_cells=start_cells,
        robot_comp=comp[start_cells[:, 0], start_cells[:, 1]],
    )


def _check_starts(
    grid: GridMap,
    start_xy: np.ndarray,
    start_cells: np.ndarray,
    centres: np.ndarray,
    robot: RobotSpec,
    wall_clearance: float,
) -> None:
    """A :class:`PlanningError` naming the first start that is not on a robot-centre cell."""
    for (x, y), rc in zip(start_xy, start_cells, strict=True):
        if not grid.in_bounds(rc):
            raise PlanningError(f"start ({x:.2f}, {y:.2f}) is outside the map")
        if not centres[rc[0], rc[1]]:
            what = (
                "inside an obstacle"
                if not grid.free[rc[0], rc[1]]
                else (
                    f"closer than the robot radius {robot.radius} m + wall clearance "
                    f"{wall_clearance} m to an obstacle"
                )
            )
            raise PlanningError(f"start ({x:.2f}, {y:.2f}) is {what}")


@dataclass(frozen=True, eq=False)
class _Sweeps:
    """Every room's sweep tasks (room by room), the dead-end rooms' tours from their doors
    (``blocks``: (task, option) runs, for ``_component_tours``), the room and cell label images
    over the cleanable floor, each room's lane angle and each cell's room."""

    tasks: list[SweepTask]
    blocks: list[list[tuple[int, int]]]
    room_img: np.ndarray
    cell_img: np.ndarray
    room_angle: list[float]
    cell_room: list[int]


def _room_sweeps(
    grid: GridMap, floor: _Floor, costs: PathCosts, params: CoverageParams, robot: RobotSpec
) -> _Sweeps:
    """Rooms by distance-transform segmentation; per room the dominant wall direction
    (``_sweep_angle``), a frame rotated to it and the boustrophedon decomposition (Choset
    2000) of the room in that frame, its lanes and its cells' sweep tasks (``_room_options``);
    in a dead-end room, the option ``_choose_option`` picks."""
    res = grid.resolution
    rooms = segment_rooms(floor.reach, floor.clear, res, params.door_width, params.min_room_area)
    doors = _dead_end_doors(grid, rooms)
    cell_labels = np.zeros(grid.shape, dtype=np.int32)
    room_img = extend_labels(rooms, floor.clean)
    spacing = params.lane_spacing(robot) / res
    hw = robot.cleaning_width / 2 / res
    room_tasks: list[list[SweepTask]] = []
    blocks: list[list[tuple[int, int]]] = []
    room_angle: list[float] = []
    cell_room: list[int] = []
    for room in range(1, int(rooms.max()) + 1):
        mask = rooms == room
        room_mask = room_img == room
        angle = _sweep_angle(mask, res)
        base = len(cell_room)
        strips = room in doors
        options = []
        for a in (angle, angle + math.pi / 2) if strips else (angle,):
            options.extend(
                _room_options(
                    grid, mask, room_mask, room, base, a, spacing, hw, params, robot, strips
                )
            )
        best, tour = 0, []
        if len(options) > 1:
            mine = floor.clean & room_mask
            best, tour = _choose_option(grid, options, angle, doors[room], mine, costs, hw, robot)
        if best > 0:
            # the global tour's local search rarely finds the strip's order by itself: it
            # starts from the room's own tour, put in whole
            first = sum(len(ts) for ts in room_tasks)
            blocks.append([(first + t, o) for t, o in tour])
        opt = options[best]
        cell_room.extend([room] * opt.n_cells)
        _paint_cells(grid, mask, opt.frame, opt.labels, base, cell_labels)
        room_tasks.append(opt.tasks)
        room_angle.append(opt.frame.angle)
    return _Sweeps(
        tasks=[t for ts in room_tasks for t in ts],
        blocks=blocks,
        room_img=room_img,
        cell_img=extend_labels(cell_labels, floor.clean),
        room_angle=room_angle,
        cell_room=cell_room,
    )


def _choose_option(
    grid: GridMap,
    options: list[_RoomOption],
    angle: float,
    door: np.ndarray,
    mine: np.ndarray,
    costs: PathCosts,
    hw: float,
    robot: RobotSpec,
) -> tuple[int, list[tuple[int, int]]]:
    """Which of a dead-end room's ``options`` gives the shortest tour of the room alone from
    its ``door`` and back, and that tour. Lanes across the usual ``angle`` must win by
    ``AXIS_MARGIN``, and the floor of ``mine`` (the room's cleanable cells) an option leaves
    to the fill-in costs it ``MISS_FACTOR`` passes over it. ``hw``: half the cleaning width in
    cells."""
    res = grid.resolution
    # straight-line hops pick a challenger cheaply; path costs judge it against plain,
    # and floor an option leaves to the fill-in costs it a pass over it, there and back
    rough = [_closed_tour(o.tasks, door, None)[0] for o in options]
    pick = {0, int(np.argmin(rough))}
    guess = {}
    tours = {}
    for i in pick:
        cost, tours[i] = _closed_tour(options[i].tasks, door, costs)
        miss = _missed(grid, options[i].tasks, mine, hw * res) * res**2
        cost += MISS_FACTOR * miss / robot.cleaning_width
        guess[i] = cost * (1 + AXIS_MARGIN if options[i].frame.angle != angle else 1)
    best = min(guess, key=guess.get)
    return best, tours[best]


def _robot_tours(
    grid: GridMap,
    floor: _Floor,
    sweeps: _Sweeps,
    costs: PathCosts,
    transit: Transit,
    params: CoverageParams,
    robot: RobotSpec,
) -> tuple[list[SweepTask], list[list[tuple[int, int]]]]:
    """The tasks and each robot's (task, option) sequence: one tour per connected part of the
    floor (``_component_tours``) cut among its robots (``_split``); with ``params.fill_in`` the
    fill-in passes (``_add_fill_in``); for a BCD plan, last, the pruning of the driven tours
    (``prune.prune_driven``)."""
    tasks = sweeps.tasks
    ends = _ends(tasks, costs, floor.start_xy)
    tours = _component_tours(grid, floor.comp, floor.robot_comp, tasks, ends, sweeps.blocks)
    pieces = _split(tasks, tours, floor.robot_comp, ends, robot)
    # the fill-in prices its own tasks: one matrix over every task end alive at a time
    del ends
    prints = Footprints(grid, floor.clean, robot.cleaning_width / 2)
    if params.fill_in:
        goal = _fill_in_goal(params.fill_in_target)
        tasks, pieces = _add_fill_in(
            grid, floor, sweeps, tasks, pieces, prints, transit, costs, params, robot, goal
        )
    # the final pruning trades the fill-in's surplus back
    keep = math.ceil(params.fill_in_target * int(floor.clean.sum())) if params.fill_in else None
    tasks, pieces = prune_driven(tasks, pieces, floor.start_xy, prints, transit, keep)
    return tasks, pieces


def _assemble(
    grid: GridMap,
    floor: _Floor,
    sweeps: _Sweeps,
    tasks: list[SweepTask],
    pieces: list[list[tuple[int, int]]],
    transit: Transit,
    params: CoverageParams,
    robot: RobotSpec,
    wall_clearance: float,
    t0: float,
) -> CoveragePlan:
    """The plan: each robot's driven path, its metrics, the room and cell graphs, the cells'
    robots; ``plan_time_s`` counted from ``t0`` (a ``time.perf_counter`` reading)."""
    # straight runs as one segment each: a follower takes each waypoint as a target
    paths = [
        without_straight_vertices(_drive(s, [path_of(tasks[t], o) for t, o in piece], transit))
        for s, piece in zip(floor.start_xy, pieces, strict=True)
    ]
    robot_tasks = [tuple(tasks[t] for t, _ in piece) for piece in pieces]
    metrics = plan_metrics(
        grid, paths, params, robot, wall_clearance=wall_clearance, cleanable_mask=floor.clean
    )
    room_graph = _room_graph(grid, sweeps.room_img, sweeps.room_angle, transit)
    cell_graph = _cell_graph(grid, sweeps.cell_img, sweeps.cell_room, robot_tasks)
    assignment = {
        c: int(r) for c, r in nx.get_node_attributes(cell_graph, "robot").items() if r >= 0
    }
    unreachable = grid.free & ~floor.clean
    return CoveragePlan(
        paths=tuple(paths),
        starts=tuple((float(x), float(y)) for x, y in floor.start_xy),
        room_labels=sweeps.room_img,
        cell_labels=sweeps.cell_img,
        room_graph=room_graph,
        cell_graph=cell_graph,
        assignment=assignment,
        tasks=tuple(robot_tasks),
        metrics=metrics,
        cleanable=floor.clean,
        unreachable=unreachable,
        unreachable_area_m2=float(unreachable.sum() * grid.resolution * grid.resolution),
        plan_time_s=time.perf_counter() - t0,
        params=params,
    )


@dataclass(frozen=True, eq=False)
class _RoomOption:
    """One way to sweep a room: its tasks, the frame and cell labels they were made in."""

    tasks: list[SweepTask]
    frame: RotatedFrame
    labels: np.ndarray
    n_cells: int


def _room_options(
    grid: GridMap,
    mask: np.ndarray,
    clean_mask: np.ndarray,
    room: int,
    base: int,
    angle: float,
    spacing: float,
    hw: float,
    params: CoverageParams,
    robot: RobotSpec,
    strips: bool,
) -> list[_RoomOption]:
    """The room's tasks with lanes at ``angle``: plain, and (with ``strips``) with a return
    strip along either lane-end side where the lanes allow one."""
    frame = frame_for(grid, mask, angle, margin=math.ceil(hw) + 1)
    rot = resample(grid, mask, frame)
    # stacked cells always merge: the lattice, clamp lanes and fill-in take their shoulders
    labels, cells = decompose(rot, max_step=max(rot.shape))
    placed = room_lanes(cells, rot, resample(grid, clean_mask, frame), labels, spacing, hw)
    lanes, shoulders = placed.lanes(), list(placed.shoulders)
    plain = _cell_tasks(room, base, cells, lanes, shoulders, None, frame, params, robot)
    out = [_RoomOption(plain, frame, labels, len(cells))]
    if strips:
        for high in (False, True):
            clipped, cell_strips = return_strips(lanes, rot, spacing, high)
            if any(cell_strips):
                ts = _cell_tasks(
                    room, base, cells, clipped, shoulders, cell_strips, frame, params, robot
                )
                out.append(_RoomOption(ts, frame, labels, len(cells)))
    return out


def _cell_tasks(
    room: int,
    base: int,
    cells: list[MonotoneCell],
    lanes: list[np.ndarray],
    shoulders: list[np.ndarray],
    strips: list[list[np.ndarray]] | None,
    frame: RotatedFrame,
    params: CoverageParams,
    robot: RobotSpec,
) -> list[SweepTask]:
    """The room's tasks: per cell its lanes, shoulder lanes and strips."""
    tasks: list[SweepTask] = []
    for k in range(1, len(cells) + 1):
        cid = base + k
        if len(lanes[k - 1]):
            tasks.extend(cell_tasks(room, cid, lanes[k - 1], frame, params, robot))
        for lane in shoulders[k - 1]:
            tasks.extend(cell_tasks(room, cid, lane[None, :], frame, params, robot))
        for strip in strips[k - 1] if strips else ():
            tasks.append(strip_task(room, cid, strip, frame, params, robot))
    return tasks


def _dead_end_doors(grid: GridMap, rooms: np.ndarray) -> dict[int, np.ndarray]:
    """The door (world point: the room's robot-centre cell nearest the middle of its border
    with the neighbour) of every room with exactly one neighbour."""
    neighbours: dict[int, list[int]] = {}
    for a, b in shared_borders(rooms):
        neighbours.setdefault(a, []).append(b)
        neighbours.setdefault(b, []).append(a)
    doors = {}
    for room, other in neighbours.items():
        if len(other) != 1:
            continue
        rc = np.argwhere((rooms == room) & _touching(rooms == other[0]))
        mid = rc.mean(axis=0)
        cell = rc[np.argmin(np.hypot(*(rc - mid).T))]
        doors[room] = grid.cell_to_world(cell.astype(float))
    return doors


def _missed(grid: GridMap, tasks: list[SweepTask], mine: np.ndarray, hw: float) -> int:
    """How many cells of ``mine`` the tasks' swaths (first variant each) leave."""
    covered = np.zeros(grid.shape, dtype=bool)
    for t in tasks:
        window, cells = footprint(grid, t.variants[0], hw)
        covered[window] |= cells
    return int((mine & ~covered).sum())


def _closed_tour(
    tasks: list[SweepTask], door: np.ndarray, costs: PathCosts | None
) -> tuple[float, list[tuple[int, int]]]:
    """Length and (task, option) order of a tour over ``tasks`` alone from ``door`` and back,
    hops priced by ``costs`` (straight lines when None: inside one room nearly the same, and
    much cheaper for the options not taken)."""
    pts = np.vstack([end_points(tasks), door[None, :]])
    ends = task_ends(tasks, cdist(pts, pts) if costs is None else costs.matrix(pts))
    tour = plan_tour(list(range(len(tasks))), len(pts) - 1, ends, closed=True)
    return tour_cost(tour, len(pts) - 1, ends), tour


def _sweep_angle(mask: np.ndarray, res: float) -> float:
    """Lanes along the dominant wall direction, the one of its two axes giving longer lanes."""
    rr, cc = np.nonzero(mask)
    sl = (slice(rr.min(), rr.max() + 1), slice(cc.min(), cc.max() + 1))
    angle = dominant_direction(np.pad(mask[sl], 3))
    if min(angle, math.pi / 2 - angle) < AXIS_SNAP:
        angle = 0.0 if angle < math.pi / 4 else math.pi / 2
    xy = np.stack([cc, rr], axis=1) * res
    spans = []
    for a in (angle, angle + math.pi / 2):
        across = -math.sin(a) * xy[:, 0] + math.cos(a) * xy[:, 1]
        spans.append(np.ptp(across))
    return angle if spans[0] <= spans[1] else angle + math.pi / 2


def _paint_cells(
    grid: GridMap,
    mask: np.ndarray,
    frame: RotatedFrame,
    labels: np.ndarray,
    base: int,
    out: np.ndarray,
) -> None:
    """Give every grid cell of the room the label of the rotated cell holding its centre."""
    rc = np.argwhere(mask)
    q = np.rint(frame.from_world(grid.cell_to_world(rc))).astype(int)
    ok = (q[:, 0] >= 0) & (q[:, 0] < frame.shape[0]) & (q[:, 1] >= 0) & (q[:, 1] < frame.shape[1])
    lab = np.zeros(len(rc), dtype=np.int32)
    lab[ok] = labels[q[ok, 0], q[ok, 1]]
    lab[lab > 0] += base
    out[rc[:, 0], rc[:, 1]] = lab


def _ends(
    tasks: Sequence[SweepTask], costs: PathCosts, start_xy: np.ndarray
) -> tuple[TaskEnds, int]:
    """The tasks' ends with path costs between them and the starts (appended after them), and
    the point index of the first start."""
    pts = end_points(tasks)
    return task_ends(tasks, costs.matrix(np.vstack([pts, start_xy]))), len(pts)


def _component_tours(
    grid: GridMap,
    comp: np.ndarray,
    robot_comp: np.ndarray,
    tasks: Sequence[SweepTask],
    priced: tuple[TaskEnds, int],
    blocks: Sequence[list[tuple[int, int]]] = (),
) -> dict[int, list[tuple[int, int]]]:
    """Per connected part of the floor holding a start: one tour over its tasks from its first
    robot's start. Where several robots share the part the tour is priced as a loop back to
    that start, so that cut into pieces, the first and the last both begin near the starts.
    ``blocks`` are tours of dead-end rooms from their doors: the tour is first planned without
    them, each is put in whole where it adds least, then the whole is improved. ``priced``:
    :func:`_ends` of the tasks."""
    ends, n_pts = priced
    first = grid.world_to_cell(np.array([t.variants[0][0] for t in tasks]).reshape(-1, 2))
    task_comp = comp[first[:, 0], first[:, 1]]
    tours = {}
    for c in np.unique(robot_comp):
        robots = np.flatnonzero(robot_comp == c)
        ids = [int(k) for k in np.flatnonzero(task_comp == c)]
        start, closed = n_pts + int(robots[0]), len(robots) > 1
        mine = [b for b in blocks if b and task_comp[b[0][0]] == c]
        inside = {t for b in mine for t, _ in b}
        tour = plan_tour([t for t in ids if t not in inside], start, ends, (), closed)
        for b in mine:
            tour = insert_run(tour, b, start, ends, closed)
        tours[int(c)] = plan_tour(ids, start, ends, tour, closed) if tour else []
    return tours


def _split(
    tasks: Sequence[SweepTask],
    tours: dict[int, list[tuple[int, int]]],
    robot_comp: np.ndarray,
    priced: tuple[TaskEnds, int],
    robot: RobotSpec,
) -> list[list[tuple[int, int]]]:
    """Each robot's (task, option) sequence: a part's tour is cut into pieces balancing the
    estimated time among the robots starting in it (``ordering.split_tour``), each piece then
    re-ordered from its robot's start. ``priced``: :func:`_ends` of the tasks."""
    ends, n_pts = priced
    pieces: list[list[tuple[int, int]]] = [[] for _ in range(len(robot_comp))]
    for c, tour in tours.items():
        robots = np.flatnonzero(robot_comp == c)
        if len(robots) == 1:
            pieces[robots[0]] = tour
            continue
        opt = np.array([ends.offset[t] + o for t, o in tour], dtype=np.int64)
        entry, exit_ = ends.entry[opt], ends.exit[opt]
        starts = n_pts + robots
        v = robot.max_vel_x
        split = split_tour(
            np.array([tasks[t].time_s for t, _ in tour]),
            np.concatenate([[0.0], ends.cost[exit_[:-1], entry[1:]]]) / v,
            ends.cost[np.ix_(entry, starts)] / v,
            ends.cost[np.ix_(exit_, starts)] / v,
        )
        for r, piece in zip(robots, split, strict=True):
            steps = [tour[i] for i in piece]
            pieces[r] = plan_tour([t for t, _ in steps], n_pts + int(r), ends, steps)
    return pieces


def _fixed(task: SweepTask, option: int) -> SweepTask:
    """The task with only the path of its chosen option (driven either way)."""
    return dataclasses.replace(task, variants=(path_of(task, option),))


def _add_fill_in(
    grid: GridMap,
    floor: _Floor,
    sweeps: _Sweeps,
    tasks: list[SweepTask],
    pieces: list[list[tuple[int, int]]],
    prints: Footprints,
    transit: Transit,
    costs: PathCosts,
    params: CoverageParams,
    robot: RobotSpec,
    goal: float,
) -> tuple[list[SweepTask], list[list[tuple[int, int]]]]:
    """Tasks and robot tours with fill-in passes for the floor the driven tours miss
    (``fill_in.fill_in_tasks``) until ``goal`` of the cleanable area is covered, in up to
    ``FILL_IN_ROUNDS`` rounds. Each sweep keeps the variant its tour chose; a pass goes to the
    robot of its floor part whose path passes closest and is inserted into its tour where it
    costs least, then the tour is improved again — which changes some transits, so the next
    round looks at what the new tours miss. Each round first drops the tasks whose floor other
    tasks already clean (``prune.prune_tasks``). ``prints`` keeps the tasks' footprints on the
    cleanable floor (``prints.clean``) for these prunings and the final one."""
    hw = robot.cleaning_width / 2
    start_xy = floor.start_xy
    for _ in range(FILL_IN_ROUNDS):
        pieces = prune_tasks(tasks, pieces, prints)
        fixed: list[SweepTask] = []
        initial = []
        driven = []
        for s, piece in zip(start_xy, pieces, strict=True):
            initial.append([(len(fixed) + k, 0) for k in range(len(piece))])
            legs = [_fixed(tasks[t], o) for t, o in piece]
            fixed.extend(legs)
            driven.append(_drive(s, [t.variants[0] for t in legs], transit))
        covered = np.zeros(grid.shape, dtype=bool)
        for path in driven:
            covered |= swath(grid, path, hw)[0]
        anchors = np.vstack([densify(path, grid.resolution) for path in driven])
        passes = fill_in_tasks(grid, covered, anchors, prints.clean, floor.reach, hw, transit, goal)
        if not passes:
            break
        trees = [cKDTree(p) for p in driven]
        owner = [r for r, piece in enumerate(initial) for _ in piece]
        for path, area in passes:
            rc = grid.world_to_cell(path[0])
            _, _, t = path_time(path, robot.max_vel_x, params.turn_cost_s, params.turn_angle_deg)
            room, cell = int(sweeps.room_img[rc[0], rc[1]]), int(sweeps.cell_img[rc[0], rc[1]])
            fixed.append(SweepTask(room, cell, (path,), area, t))
            near = [
                tree.query(path[[0, -1]])[0].min()
                if floor.robot_comp[r] == floor.comp[rc[0], rc[1]]
                else np.inf
                for r, tree in enumerate(trees)
            ]
            owner.append(int(np.argmin(near)))
        tasks = fixed
        ends, n_pts = _ends(tasks, costs, start_xy)
        pieces = [
            plan_tour([k for k, o in enumerate(owner) if o == r], n_pts + r, ends, initial[r])
            for r in range(len(start_xy))
        ]
    return tasks, pieces


def _fill_in_goal(target: float) -> float:
    """What the fill-in aims at: ``target`` plus ``FILL_IN_SURPLUS`` of what it leaves."""
    return target + FILL_IN_SURPLUS * (1.0 - target)


def _drive(start: np.ndarray, legs: Sequence[np.ndarray], transit: Transit) -> np.ndarray:
    """The robot's whole path: transit to each task's chosen path, then drive it."""
    parts = [start[None, :]]
    p = start
    for v in legs:
        parts.append(transit.path(p, v[0])[1:])
        parts.append(v[1:])
        p = v[-1]
    return without_repeats(np.vstack(parts))


def _room_graph(
    grid: GridMap, room_img: np.ndarray, angles: Sequence[float], transit: Transit
) -> nx.Graph:
    g = nx.Graph()
    res = grid.resolution
    for room in range(1, int(room_img.max()) + 1):
        g.add_node(
            room, area_m2=float((room_img == room).sum() * res * res), angle=angles[room - 1]
        )
    for (a, b), _n in shared_borders(room_img).items():
        rr, cc = np.nonzero((room_img == a) & _touching(room_img == b))
        door = grid.cell_to_world(np.array([rr.mean(), cc.mean()]))
        rc = transit.snap(door)
        door = grid.cell_to_world(np.array(rc, dtype=float))
        g.add_edge(a, b, door=(float(door[0]), float(door[1])), width_m=float(len(rr) * res))
    for room in g.nodes:
        doors = [g.edges[room, o]["door"] for o in g.neighbors(room)]
        g.nodes[room]["entry_points"] = np.array(doors, dtype=float).reshape(-1, 2)
    return g


def _cell_graph(
    grid: GridMap,
    cell_img: np.ndarray,
    cell_room: Sequence[int],
    robot_tasks: Sequence[Sequence[SweepTask]],
) -> nx.Graph:
    g = nx.Graph()
    res = grid.resolution
    areas = np.bincount(cell_img.ravel(), minlength=len(cell_room) + 1)
    share: dict[int, dict[int, float]] = {}
    entries: dict[int, list[np.ndarray]] = {}
    for robot, tasks in enumerate(robot_tasks):
        for t in tasks:
            share.setdefault(t.cell, {}).setdefault(robot, 0.0)
            share[t.cell][robot] += t.area_m2
            entries.setdefault(t.cell, []).extend(v[0] for v in t.variants)
    for cid, room in enumerate(cell_room, start=1):
        owners = share.get(cid, {})
        robot = max(owners, key=owners.get) if owners else -1
        pts = np.array(entries.get(cid, []), dtype=float).reshape(-1, 2)
        g.add_node(
            cid, room=room, area_m2=float(areas[cid] * res * res), robot=robot, entry_points=pts
        )
    for (a, b), n in shared_borders(cell_img).items():
        g.add_edge(a, b, border_m=float(n * res))
    return g


def _touching(mask: np.ndarray) -> np.ndarray:
    return ndimage.binary_dilation(mask, structure=ndimage.generate_binary_structure(2, 1))
