"""The generated family of stress worlds (fleet.bench.world_family): every member loads as a
world, its passages are as wide as asked (measured as the free gap on the grid), its starts are
free, and its rooms are joined for a robot centre (clearance ≥ radius + wall clearance) on the
grid the coverage plans are made on."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from fleet.bench.world_family import FAMILY, FamilyMember, layout, members, write_world
from fleet.params import load_fleet_config
from fleet.world import load_world
from planners.grid import GridMap, clearance

CFG = load_fleet_config()
CENTRE_CLEARANCE = CFG.robot.radius + CFG.coordinator.wall_clearance
# the coverage planner's grid (configs/fleet.yaml, coverage:), finer than the transit graph's
PLAN_RES = 0.025


def _free_run(grid: GridMap, point: tuple[float, float], across: str) -> float:
    """The length (m) of the run of free cells through ``point`` along ``across``."""
    free = ~(grid.occupied | grid.unknown)
    r, c = grid.world_to_cell(np.array(point))
    line, i = (free[:, c], r) if across == "y" else (free[r, :], c)
    assert line[i], f"{point} is not free"
    blocked = np.flatnonzero(~line)
    below, above = blocked[blocked < i], blocked[blocked > i]
    assert len(below) and len(above), f"the run through {point} reaches the map's edge"
    return float(above[0] - below[-1] - 1) * grid.resolution


def test_the_family_covers_the_widths_lengths_and_shapes_asked() -> None:
    names = [m.name for m in FAMILY]
    assert names == [
        "c0.45x2.5",
        "c0.6x1",
        "c0.6x4",
        "c0.75x2.5",
        "c0.9x2.5",
        "door0.8",
        "L0.6",
        "3rooms0.6",
    ]
    assert {m.width for m in FAMILY if m.shape == "straight"} == {0.45, 0.6, 0.75, 0.9}
    assert {m.length for m in FAMILY if m.shape == "straight"} == {1.0, 2.5, 4.0}
    assert members("L0.6,door0.8") == [FAMILY[6], FAMILY[5]]
    with pytest.raises(ValueError, match="c9x9"):
        members("c9x9")


@pytest.mark.parametrize("member", FAMILY, ids=lambda m: m.name)
def test_a_member_loads_with_free_starts_and_passages_as_wide_as_asked(
    member: FamilyMember, tmp_path: Path
) -> None:
    world = load_world(write_world(member, tmp_path), CFG.robot.radius)
    plan = layout(member)
    assert len(world.starts) == 4 and len(world.furniture) == len(plan.room_points) + 1
    assert np.all(world.clearance(np.array([s[:2] for s in world.starts])) >= CENTRE_CLEARANCE)
    grid = world.grid(PLAN_RES)
    for gauge in plan.gauges:
        measured = _free_run(grid, gauge.point, gauge.across)
        # the rasterizer marks every cell an obstacle touches: at most one cell is lost
        assert gauge.width - PLAN_RES - 1e-9 <= measured <= gauge.width + 1e-9, (gauge, measured)


@pytest.mark.parametrize("member", FAMILY, ids=lambda m: m.name)
def test_a_members_rooms_and_starts_are_joined_for_a_robot_centre(
    member: FamilyMember, tmp_path: Path
) -> None:
    world = load_world(write_world(member, tmp_path), CFG.robot.radius)
    plan = layout(member)
    grid = world.grid(PLAN_RES)
    labels, _ = ndimage.label(clearance(grid) >= CENTRE_CLEARANCE)
    places = np.array([s[:2] for s in plan.starts] + list(plan.room_points))
    rc = grid.world_to_cell(places)
    found = labels[rc[:, 0], rc[:, 1]]
    assert np.all(found > 0) and len(set(found)) == 1, (places, found)
    # the starts are in the first room and in the last: the passages are crossed both ways
    centres = np.array(plan.room_points)
    rooms = {int(np.argmin(np.hypot(*(centres - s[:2]).T))) for s in plan.starts}
    assert rooms == {0, len(plan.room_points) - 1}


def test_a_member_is_written_the_same_every_time(tmp_path: Path) -> None:
    first = write_world(FAMILY[-1], tmp_path / "a").read_text()
    assert write_world(FAMILY[-1], tmp_path / "b").read_text() == first
