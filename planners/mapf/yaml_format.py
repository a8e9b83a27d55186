"""libMultiRobotPlanning's YAML formats (Hönig et al.; github.com/whoenig/libMultiRobotPlanning).

Input::

    map: {dimensions: [W, H], obstacles: [[x, y], ...]}
    agents: [{name: agent0, start: [x, y], goal: [x, y]}, ...]

Output::

    statistics: {cost, makespan, runtime, highLevelExpanded, lowLevelExpanded}
    schedule: {agent0: [{x: .., y: .., t: ..}, ...], ...}

x is the column and y the row (``MapfInstance`` cells are ``(row, col) = (y, x)``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import yaml

from planners.mapf.model import MapfInstance, MapfResult
from planners.mapf.movingai import FormatError


def _pair(value: Any, where: str) -> tuple[int, int]:
    if not (isinstance(value, list | tuple) and len(value) == 2):
        raise FormatError(f"{where}: expected [x, y], got {value!r}")
    try:
        return int(value[0]), int(value[1])
    except (TypeError, ValueError) as err:
        raise FormatError(f"{where}: expected integers, got {value!r}") from err


def instance_from_mapping(data: Any, source: str = "<yaml>") -> MapfInstance:
    if not isinstance(data, dict):
        raise FormatError(f"{source}: top level must be a mapping with 'map' and 'agents'")
    grid = data.get("map")
    if not isinstance(grid, dict):
        raise FormatError(f"{source}: map: missing or not a mapping")
    width, height = _pair(grid.get("dimensions"), f"{source}: map.dimensions")
    if width <= 0 or height <= 0:
        raise FormatError(f"{source}: map.dimensions must be positive, got {[width, height]}")
    free = np.ones((height, width), dtype=bool)
    for j, obstacle in enumerate(grid.get("obstacles") or []):
        x, y = _pair(obstacle, f"{source}: map.obstacles[{j}]")
        if not (0 <= x < width and 0 <= y < height):
            raise FormatError(f"{source}: map.obstacles[{j}] = {[x, y]} is outside the map")
        free[y, x] = False
    agents = data.get("agents")
    if not isinstance(agents, list) or not agents:
        raise FormatError(f"{source}: agents: expected a non-empty list")
    names, starts, goals = [], [], []
    for j, agent in enumerate(agents):
        if not isinstance(agent, dict):
            raise FormatError(f"{source}: agents[{j}]: expected a mapping")
        names.append(str(agent.get("name", f"agent{j}")))
        for key, out in (("start", starts), ("goal", goals)):
            x, y = _pair(agent.get(key), f"{source}: agents[{j}].{key}")
            out.append((y, x))
    if len(set(names)) != len(names):
        raise FormatError(f"{source}: agents: names must be unique")
    return MapfInstance(free, tuple(starts), tuple(goals), tuple(names))


def read_instance(path: str | Path) -> MapfInstance:
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as err:
        raise FormatError(f"{path}: not valid YAML ({err})") from err
    return instance_from_mapping(data, str(path))


def instance_to_mapping(instance: MapfInstance) -> dict[str, Any]:
    rows, cols = instance.shape
    obstacles = [[int(c), int(r)] for r, c in np.argwhere(~instance.free)]
    agents = [
        {"name": name, "start": [s[1], s[0]], "goal": [g[1], g[0]]}
        for name, s, g in zip(instance.names, instance.starts, instance.goals, strict=True)
    ]
    return {"map": {"dimensions": [cols, rows], "obstacles": obstacles}, "agents": agents}


def result_to_mapping(instance: MapfInstance, result: MapfResult) -> dict[str, Any]:
    """The output format; raises ValueError when the result holds no solution."""
    if result.solution is None:
        raise ValueError(f"no schedule to write: status {result.status}")
    schedule = {
        name: [{"x": c, "y": r, "t": t} for t, (r, c) in enumerate(path)]
        for name, path in zip(instance.names, result.solution.paths, strict=True)
    }
    return {
        "statistics": {
            "cost": result.soc,
            "makespan": result.makespan,
            "runtime": round(result.runtime_s, 6),
            "highLevelExpanded": result.expanded_high,
            "lowLevelExpanded": result.expanded_low,
        },
        "schedule": schedule,
    }


def schedule_from_mapping(instance: MapfInstance, data: Any, source: str = "<yaml>") -> list:
    """Paths ``[(row, col), ...]`` per agent of ``instance`` from an output-format mapping."""
    schedule = data.get("schedule") if isinstance(data, dict) else None
    if not isinstance(schedule, dict):
        raise FormatError(f"{source}: schedule: missing or not a mapping")
    paths = []
    for name in instance.names:
        steps = schedule.get(name)
        if not isinstance(steps, list) or not steps:
            raise FormatError(f"{source}: schedule.{name}: missing or empty")
        ordered = sorted(steps, key=lambda s: int(s["t"]))
        if [int(s["t"]) for s in ordered] != list(range(len(ordered))):
            raise FormatError(f"{source}: schedule.{name}: times must be 0, 1, 2, ...")
        paths.append([(int(s["y"]), int(s["x"])) for s in ordered])
    return paths


def write_yaml(path: str | Path, data: dict[str, Any]) -> None:
    Path(path).write_text(yaml.safe_dump(data, sort_keys=False, default_flow_style=None))
