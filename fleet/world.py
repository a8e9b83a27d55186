"""Worlds: the floor plans the simulator runs and the planners plan on.

Two kinds of file load as a world:

* a **world YAML** (``configs/worlds/*.yaml``) with walls as thick segments, furniture as boxes
  or circles, charging docks (``dock:`` one pose, or ``docks:`` a list of poses; a pose is
  where a robot stands on the dock, heading away from the dock's body) and start poses — or
  with ``map:`` naming a ROS map_server YAML whose image gives the walls (a map world's docks
  have no body drawn: the image shows what is there);
* a **ROS map_server YAML** (``image``, ``resolution``, ``origin``, ``negate``,
  ``occupied_thresh``, ``free_thresh``, optional ``mode``), as written by ``map_saver``.

Every error is a :class:`fleet.config.ConfigError` naming the file and the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, ImageDraw
from scipy import ndimage

from fleet.config import ConfigError, read_yaml, unknown_field
from planners.grid import GridMap, reachable

Pose = tuple[float, float, float]

WORLD_FIELDS = {
    "name",
    "description",
    "wall_thickness",
    "walls",
    "furniture",
    "dock",
    "docks",
    "starts",
    "map",
}
FURNITURE_FIELDS = {"name", "type", "center", "size", "angle", "radius"}
ROS_MAP_FIELDS = {
    "image",
    "resolution",
    "origin",
    "negate",
    "occupied_thresh",
    "free_thresh",
    "mode",
}
CIRCLE_SIDES = 24
# a stored map in the world's frame has (nearly) no free floor outside the world's outer walls;
# one whose origin is off has a strip of it there
MAP_OUTSIDE_MAX = 0.02
# the grid (m) starts and docks are checked on for their clearance and reach
CLEARANCE_RES = 0.025
DOCK_SIZE = (0.35, 0.2)


@dataclass(frozen=True, eq=False)
class Furniture:
    name: str
    polygon: np.ndarray  # (K, 2) convex, counter-clockwise


@dataclass(frozen=True, eq=False)
class World:
    """A static floor plan: obstacle polygons (vector worlds) or an occupancy image (map worlds)."""

    name: str
    source: Path
    walls: tuple[np.ndarray, ...]
    furniture: tuple[Furniture, ...]
    map_grid: GridMap | None
    docks: tuple[Pose, ...]
    starts: tuple[Pose, ...]
    bounds: tuple[float, float, float, float]

    @property
    def dock(self) -> Pose | None:
        """The first dock (None without one): where the robots' tour starts from."""
        return self.docks[0] if self.docks else None

    @property
    def polygons(self) -> tuple[np.ndarray, ...]:
        """All static obstacle polygons of a vector world (walls, furniture, dock)."""
        return self.walls + tuple(f.polygon for f in self.furniture)

    def grid(self, resolution: float = 0.05) -> GridMap:
        """Rasterize the world; a cell touched by an obstacle is occupied."""
        if self.map_grid is not None:
            if math.isclose(resolution, self.map_grid.resolution):
                return self.map_grid
            return _resample(self.map_grid, resolution)
        xmin, ymin, xmax, ymax = self.bounds
        cols = math.ceil((xmax - xmin) / resolution)
        rows = math.ceil((ymax - ymin) / resolution)
        img = Image.new("1", (cols, rows), 0)
        draw = ImageDraw.Draw(img)
        for poly in self.polygons:
            pix = [((x - xmin) / resolution - 0.5, (y - ymin) / resolution - 0.5) for x, y in poly]
            draw.polygon(pix, fill=1, outline=1)
        occ = np.array(img, dtype=bool)
        return GridMap(occ, np.zeros_like(occ), resolution, (xmin, ymin))

    def clearance(self, xy: np.ndarray, resolution: float = CLEARANCE_RES) -> np.ndarray:
        """Distance (m) from points to the nearest occupied or unknown cell (0 outside the map)."""
        g = self.grid(resolution)
        blocked = g.occupied | g.unknown
        dist = ndimage.distance_transform_edt(~blocked) * resolution - resolution / 2
        rc = g.world_to_cell(np.atleast_2d(xy))
        inside = g.in_bounds(rc)
        out = np.zeros(len(rc))
        out[inside] = dist[rc[inside, 0], rc[inside, 1]]
        return np.maximum(out, 0.0)

    def start_poses(self, n: int, robot_radius: float, spacing: float = 0.55) -> list[Pose]:
        """``n`` start poses: the listed ones first, then free poses nearest the dock.

        Extra poses lie in the free space reachable from the first start (or the dock, or the
        most open point of the map), at least ``spacing`` apart and ``robot_radius + 0.1`` m from
        any obstacle.
        """
        poses = list(self.starts[:n])
        if len(poses) == n:
            return poses
        res = 0.05
        g = self.grid(res)
        blocked = g.occupied | g.unknown
        clear = ndimage.distance_transform_edt(~blocked) * res
        ok = clear >= robot_radius + 0.1
        labels, _ = ndimage.label(ok)
        if self.starts:
            anchor = np.array(self.starts[0][:2])
        elif self.dock is not None:
            anchor = np.array(self.dock[:2])
        else:
            anchor = g.cell_to_world(np.unravel_index(np.argmax(clear), clear.shape))
        arc = g.world_to_cell(anchor)
        near = labels == labels[tuple(np.clip(arc, 0, np.array(clear.shape) - 1))]
        if not near.any():
            near = ok
        cells = np.argwhere(near)
        pts = g.cell_to_world(cells)
        order = np.argsort(np.hypot(*(pts - anchor).T), kind="stable")
        heading = self.starts[0][2] if self.starts else (self.dock[2] if self.dock else 0.0)
        for p in pts[order]:
            if all(math.hypot(p[0] - q[0], p[1] - q[1]) >= spacing for q in poses):
                poses.append((float(p[0]), float(p[1]), heading))
                if len(poses) == n:
                    return poses
        raise ConfigError(
            f"{self.source}: room for only {len(poses)} robots near the start, {n} requested"
        )


def load_world(path: str | Path, robot_radius: float | None = None) -> World:
    """Load a world YAML or a ROS map_server YAML. Its start poses (and dock) must lie in the
    world and the starts outside obstacles; with ``robot_radius`` the starts must also keep
    that clearance from obstacles and from each other's robots (a world loaded for its floor
    plan alone needs no robot)."""
    path = Path(path)
    data = read_yaml(path)
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping at the top level")
    if "image" in data:
        world = _world_from_ros_map(path, data, starts=(), docks=(), name=path.stem)
    else:
        world = _world_from_yaml(path, data)
    _check_starts(world, robot_radius, _dock_fields(data))
    return world


def load_ros_map(path: str | Path) -> GridMap:
    """Load a ROS map_server map (YAML + PGM/PNG) as a GridMap."""
    path = Path(path)
    data = read_yaml(path)
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping at the top level")
    return _parse_ros_map(path, data)


def on_stored_map(world: World, map_path: str | Path) -> World:
    """``world`` with its floor plan replaced by the stored ROS map at ``map_path`` (the one
    `fleet explore` writes, in the world's frame: the robots' SLAM starts at their known start
    poses); its name, dock and start poses stay the world's. The map must be in the world's
    frame: every listed start pose on its known floor, and at most ``MAP_OUTSIDE_MAX`` of its
    free area outside the world's bounds; a ConfigError naming the file says which it breaks."""
    path = Path(map_path)
    grid = load_ros_map(path)
    frame = f"{path}: origin: the map is not in the frame of the world {world.source}"
    poses = [(f"starts[{i}]", pose) for i, pose in enumerate(world.starts)]
    if not poses and world.dock is not None:
        poses = [("dock", world.dock)]
    for field, (x, y, _) in poses:
        rc = grid.world_to_cell(np.array([x, y]))
        if not (grid.in_bounds(rc) and grid.free[rc[0], rc[1]]):
            raise ConfigError(f"{frame}: its {field} ({x}, {y}) is not on the map's known floor")
    xy = grid.cell_to_world(np.argwhere(grid.free))
    xmin, ymin, xmax, ymax = world.bounds
    outside = ~((xy[:, 0] >= xmin) & (xy[:, 0] <= xmax) & (xy[:, 1] >= ymin) & (xy[:, 1] <= ymax))
    if outside.mean() > MAP_OUTSIDE_MAX:
        raise ConfigError(
            f"{frame}: {100 * outside.mean():.0f} % of the map's free floor lies outside the "
            f"world's bounds {world.bounds}"
        )
    rows, cols = grid.shape
    ox, oy = grid.origin
    bounds = (ox, oy, ox + cols * grid.resolution, oy + rows * grid.resolution)
    return World(world.name, path, (), (), grid, world.docks, world.starts, bounds)


def shift_world(world: World, dx: float, dy: float) -> World:
    """``world`` moved by (dx, dy) metres: walls, furniture, dock, start poses, bounds (and the
    occupancy image's origin of a map world). Moving the world by a fraction of a cell puts
    its walls off round coordinates, as real walls are; the SLAM map's cell lattice then has
    to follow them (``agents.slam.submaps.wall_lattice``)."""
    grid = world.map_grid
    if grid is not None:
        grid = replace(grid, origin=(grid.origin[0] + dx, grid.origin[1] + dy))
    x0, y0, x1, y1 = world.bounds
    bounds = (x0 + dx, y0 + dy, x1 + dx, y1 + dy)
    return _rigid(world, 0.0, np.array([dx, dy]), world.name, grid, bounds)


def turned_world(world: World, degrees: float) -> World:
    """``world`` turned by ``degrees`` (counter-clockwise) about the centre of its bounds:
    walls, furniture, docks and start poses, its bounds the box round its turned bounds; named
    ``NAME-turnedD``. A robot maps a real home in the frame it started in, so its walls run
    along no axis of the map: a turned world is how that is tried on a known plan. Vector worlds
    only; a ConfigError names a map world's file."""
    if world.map_grid is not None:
        raise ConfigError(f"{world.source}: a map image cannot be turned; only a vector world")
    a = math.radians(degrees)
    x0, y0, x1, y1 = world.bounds
    centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    corners = (np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]) - centre) @ rot.T + centre
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    bounds = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
    name = f"{world.name}-turned{degrees:g}"
    return _rigid(world, a, centre - rot @ centre, name, None, bounds)


def _rigid(
    world: World,
    angle: float,
    offset: np.ndarray,
    name: str,
    map_grid: GridMap | None,
    bounds: tuple[float, float, float, float],
) -> World:
    """``world``'s walls, furniture, docks and start poses turned by ``angle`` (rad) about the
    origin and moved by ``offset``, with the name, map image and bounds given."""
    rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])

    def move(points: np.ndarray) -> np.ndarray:
        return np.asarray(points, dtype=float) @ rot.T + offset

    def move_pose(pose: Pose) -> Pose:
        x, y = move(np.array(pose[:2]))
        heading = math.remainder(pose[2] + angle, 2 * math.pi) if angle else pose[2]
        return (float(x), float(y), heading)

    return World(
        name,
        world.source,
        tuple(move(w) for w in world.walls),
        tuple(Furniture(f.name, move(f.polygon)) for f in world.furniture),
        map_grid,
        tuple(move_pose(d) for d in world.docks),
        tuple(move_pose(p) for p in world.starts),
        bounds,
    )


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{where}: expected a finite number, got {value!r}")
    return float(value)


def _vector(value: Any, n: int, where: str) -> tuple[float, ...]:
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise ConfigError(f"{where}: expected a list of {n} numbers, got {value!r}")
    return tuple(_number(v, f"{where}[{i}]") for i, v in enumerate(value))


def _box(center: tuple[float, ...], size: tuple[float, ...], angle: float) -> np.ndarray:
    hx, hy = size[0] / 2, size[1] / 2
    corners = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    c, s = math.cos(angle), math.sin(angle)
    return corners @ np.array([[c, s], [-s, c]]) + np.array(center[:2])


def _thick_segment(seg: tuple[float, ...], thickness: float) -> np.ndarray:
    x1, y1, x2, y2 = seg
    length = math.hypot(x2 - x1, y2 - y1)
    angle = math.atan2(y2 - y1, x2 - x1)
    # Extend by half the thickness so walls meeting at a corner close it.
    return _box(((x1 + x2) / 2, (y1 + y2) / 2), (length + thickness, thickness), angle)


def _world_from_yaml(path: Path, data: dict) -> World:
    unknown = sorted(set(data) - WORLD_FIELDS, key=str)
    if unknown:
        raise unknown_field(f"{path}: {unknown[0]}", str(unknown[0]), WORLD_FIELDS)
    name = data.get("name", path.stem)
    if not isinstance(name, str):
        raise ConfigError(f"{path}: name: expected a string")
    starts = tuple(
        _vector(s, 3, f"{path}: starts[{i}]") for i, s in enumerate(_list(data, "starts", path))
    )
    docks = _docks(data, path)
    if "map" in data:
        if data.get("walls") or data.get("furniture"):
            raise ConfigError(
                f"{path}: map: a map world takes its walls from the image; remove walls/furniture"
            )
        if not isinstance(data["map"], str):
            raise ConfigError(f"{path}: map: expected the path of a ROS map YAML")
        map_path = (path.parent / data["map"]).resolve()
        if not map_path.is_file():
            raise ConfigError(f"{path}: map: ROS map file not found: {map_path}")
        map_data = read_yaml(map_path)
        if not isinstance(map_data, dict):
            raise ConfigError(f"{map_path}: expected a mapping at the top level")
        return _world_from_ros_map(map_path, map_data, starts, docks, name, source=path)

    thickness = _number(data.get("wall_thickness", 0.1), f"{path}: wall_thickness")
    if thickness <= 0:
        raise ConfigError(f"{path}: wall_thickness: must be > 0")
    walls = []
    for i, w in enumerate(_list(data, "walls", path)):
        seg = _vector(w, 4, f"{path}: walls[{i}]")
        if math.hypot(seg[2] - seg[0], seg[3] - seg[1]) == 0:
            raise ConfigError(f"{path}: walls[{i}]: zero length")
        walls.append(_thick_segment(seg, thickness))
    if not walls:
        raise ConfigError(f"{path}: walls: a world needs at least one wall")
    furniture = [
        _furniture(f, f"{path}: furniture[{i}]")
        for i, f in enumerate(_list(data, "furniture", path))
    ]
    for i, dock in enumerate(docks):
        # The dock's body stands behind its pose, against the wall it faces away from.
        back = (dock[0] - math.cos(dock[2]) * 0.3, dock[1] - math.sin(dock[2]) * 0.3)
        name_i = "dock" if i == 0 else f"dock {i}"
        furniture.append(Furniture(name_i, _box(back, DOCK_SIZE[::-1], dock[2])))
    pts = np.concatenate(walls)
    bounds = (
        float(pts[:, 0].min()),
        float(pts[:, 1].min()),
        float(pts[:, 0].max()),
        float(pts[:, 1].max()),
    )
    return World(name, path, tuple(walls), tuple(furniture), None, docks, starts, bounds)


def _docks(data: dict, path: Path) -> tuple[Pose, ...]:
    """The world's docks: ``dock:`` (one pose) and ``docks:`` (a list), the first first."""
    out = []
    if data.get("dock") is not None:
        out.append(_vector(data["dock"], 3, f"{path}: dock"))
    out += [_vector(d, 3, f"{path}: docks[{i}]") for i, d in enumerate(_list(data, "docks", path))]
    return tuple(out)


def _dock_fields(data: dict) -> list[str]:
    """The fields of the file that name the world's docks, in :func:`_docks`' order."""
    first = ["dock"] if data.get("dock") is not None else []
    extra = data.get("docks")
    return first + [f"docks[{i}]" for i in range(len(extra) if isinstance(extra, list) else 0)]


def _list(data: dict, key: str, path: Path) -> list:
    value = data.get(key) or []
    if not isinstance(value, list):
        raise ConfigError(f"{path}: {key}: expected a list")
    return value


def _furniture(item: Any, where: str) -> Furniture:
    if not isinstance(item, dict):
        raise ConfigError(f"{where}: expected a mapping")
    unknown = sorted(set(item) - FURNITURE_FIELDS, key=str)
    if unknown:
        raise unknown_field(f"{where}.{unknown[0]}", str(unknown[0]), FURNITURE_FIELDS)
    kind = item.get("type", "box")
    name = str(item.get("name", kind))
    if "center" not in item:
        raise ConfigError(f"{where}.center: required field is missing")
    center = _vector(item["center"], 2, f"{where}.center")
    if kind == "box":
        if "size" not in item:
            raise ConfigError(f"{where}.size: required field is missing")
        size = _vector(item["size"], 2, f"{where}.size")
        if min(size) <= 0:
            raise ConfigError(f"{where}.size: must be > 0")
        angle = math.radians(_number(item.get("angle", 0.0), f"{where}.angle"))
        return Furniture(name, _box(center, size, angle))
    if kind == "circle":
        if "radius" not in item:
            raise ConfigError(f"{where}.radius: required field is missing")
        r = _number(item["radius"], f"{where}.radius")
        if r <= 0:
            raise ConfigError(f"{where}.radius: must be > 0")
        # Circumscribed polygon, so the polygon contains the true circle.
        a = np.arange(CIRCLE_SIDES) * 2 * math.pi / CIRCLE_SIDES
        rr = r / math.cos(math.pi / CIRCLE_SIDES)
        return Furniture(
            name, np.stack([center[0] + rr * np.cos(a), center[1] + rr * np.sin(a)], 1)
        )
    raise ConfigError(f"{where}.type: must be 'box' or 'circle', got {kind!r}")


def _parse_ros_map(path: Path, data: dict) -> GridMap:
    unknown = sorted(set(data) - ROS_MAP_FIELDS, key=str)
    if unknown:
        raise unknown_field(f"{path}: {unknown[0]}", str(unknown[0]), ROS_MAP_FIELDS)
    for key in ("image", "resolution", "origin"):
        if key not in data:
            raise ConfigError(f"{path}: {key}: required field is missing")
    if not isinstance(data["image"], str):
        raise ConfigError(f"{path}: image: expected a file name")
    res = _number(data["resolution"], f"{path}: resolution")
    if res <= 0:
        raise ConfigError(f"{path}: resolution: must be > 0")
    origin = _vector(data["origin"], 3, f"{path}: origin")
    if abs(origin[2]) > 1e-9:
        raise ConfigError(f"{path}: origin: a rotated origin (yaw {origin[2]}) is not supported")
    negate = data.get("negate", 0)
    if negate not in (0, 1):
        raise ConfigError(f"{path}: negate: must be 0 or 1, got {negate!r}")
    occ_t = _number(data.get("occupied_thresh", 0.65), f"{path}: occupied_thresh")
    free_t = _number(data.get("free_thresh", 0.196), f"{path}: free_thresh")
    if not 0.0 <= free_t < occ_t <= 1.0:
        raise ConfigError(
            f"{path}: free_thresh/occupied_thresh: need 0 ≤ free_thresh < occupied_thresh ≤ 1, "
            f"got {free_t} and {occ_t}"
        )
    mode = data.get("mode", "trinary")
    if mode not in ("trinary", "scale", "raw"):
        raise ConfigError(f"{path}: mode: must be trinary, scale or raw, got {mode!r}")
    image_path = path.parent / data["image"]
    try:
        with Image.open(image_path) as im:
            pixels = np.asarray(im.convert("L"), dtype=np.float64)
    except FileNotFoundError:
        raise ConfigError(f"{path}: image: file not found: {image_path}") from None
    except OSError as e:
        raise ConfigError(f"{path}: image: cannot read {image_path}: {e}") from None
    if mode == "raw":
        occ = pixels >= 100
        unk = pixels == 255
    else:
        p = pixels / 255.0 if negate else (255.0 - pixels) / 255.0
        occ = p > occ_t
        unk = ~occ & ~(p < free_t)
    # Image row 0 is the top (highest y); grid row 0 is the lowest y.
    occ, unk = np.flipud(occ).copy(), np.flipud(unk).copy()
    if not (~occ & ~unk).any():
        raise ConfigError(
            f"{path}: image {image_path.name} has no free cell (check negate and the thresholds)"
        )
    return GridMap(occ, unk, res, (origin[0], origin[1]))


def _world_from_ros_map(
    path: Path,
    data: dict,
    starts: tuple,
    docks: tuple[Pose, ...],
    name: str,
    source: Path | None = None,
) -> World:
    g = _parse_ros_map(path, data)
    rows, cols = g.shape
    ox, oy = g.origin
    bounds = (ox, oy, ox + cols * g.resolution, oy + rows * g.resolution)
    return World(name, source or path, (), (), g, docks, starts, bounds)


def _resample(g: GridMap, resolution: float) -> GridMap:
    """Resample a map grid to another resolution; a cell is occupied if any source cell is."""
    rows, cols = g.shape
    new_rows = math.ceil(rows * g.resolution / resolution)
    new_cols = math.ceil(cols * g.resolution / resolution)
    centres = np.stack(np.meshgrid(np.arange(new_rows), np.arange(new_cols), indexing="ij"), -1)
    xy = np.array(g.origin) + (centres[..., ::-1] + 0.5) * resolution
    if resolution >= g.resolution:
        k = math.ceil(resolution / g.resolution)
        occ = ndimage.maximum_filter(g.occupied, size=k)
        unk = ndimage.maximum_filter(g.unknown, size=k)
    else:
        occ, unk = g.occupied, g.unknown
    rc = np.clip(g.world_to_cell(xy), 0, np.array([rows - 1, cols - 1]))
    return GridMap(
        occ[rc[..., 0], rc[..., 1]],
        unk[rc[..., 0], rc[..., 1]] & ~occ[rc[..., 0], rc[..., 1]],
        resolution,
        g.origin,
    )


def _check_starts(world: World, radius: float | None, dock_fields: list[str]) -> None:
    """Starts and docks lie in the world, outside obstacles; with ``radius`` they keep it from
    obstacles, starts from each other's robots, and a robot centre reaches each from the
    first (a dock in a closed-off room is out of reach). Each error names the file's field."""
    if not world.starts and not world.docks:
        return
    where = world.source
    named = [(f"starts[{i}]", s) for i, s in enumerate(world.starts)]
    named += list(zip(dock_fields, world.docks, strict=True))
    xy = np.array([p[:2] for _, p in named])
    xmin, ymin, xmax, ymax = world.bounds
    clear = world.clearance(xy)
    for (field, pose), c in zip(named, clear, strict=False):
        x, y = pose[0], pose[1]
        if not (xmin <= x <= xmax and ymin <= y <= ymax):
            raise ConfigError(f"{where}: {field}: ({x}, {y}) lies outside the world {world.bounds}")
        if c <= 0 or (radius is not None and c < radius):
            near = "" if radius is None else f" or closer than the robot radius {radius} m to one"
            raise ConfigError(
                f"{where}: {field}: ({x}, {y}) is inside an obstacle{near} (clearance {c:.3f} m)"
            )
    if radius is None:
        return
    for i in range(len(world.starts)):
        for j in range(i):
            a, b = world.starts[i], world.starts[j]
            if math.hypot(a[0] - b[0], a[1] - b[1]) < 2 * radius:
                raise ConfigError(f"{where}: starts[{i}]: overlaps starts[{j}]")
    _check_reach(world, named, radius)


def _check_reach(world: World, named: list[tuple[str, Pose]], radius: float) -> None:
    """Every pose of ``named`` lies on floor a robot centre reaches from the first one's
    (cells keeping ``radius`` from obstacles, as :meth:`World.clearance` measures it)."""
    res = CLEARANCE_RES
    g = world.grid(res)
    dist = ndimage.distance_transform_edt(~(g.occupied | g.unknown)) * res - res / 2
    rc = np.clip(g.world_to_cell(np.array([p[:2] for _, p in named])), 0, np.array(dist.shape) - 1)
    reach = reachable(dist >= radius, rc[:1])
    for (field, pose), (r, c) in zip(named, rc, strict=True):
        if not reach[r, c]:
            raise ConfigError(
                f"{world.source}: {field}: ({pose[0]}, {pose[1]}) is out of reach: no way for "
                f"a robot of radius {radius} m from {named[0][0]}"
            )
