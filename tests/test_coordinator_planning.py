"""The coordinator's coverage planner: the same world and fleet size give the same plan."""

from __future__ import annotations

import numpy as np
import pytest

from fleet.config import resolve_world
from fleet.coordinator.planning import SNAP_M, CoveragePlanner
from fleet.params import load_fleet_config
from fleet.world import load_world
from planners.coverage import plan_coverage


@pytest.fixture(scope="module")
def small():
    cfg = load_fleet_config()
    world = load_world(resolve_world("small"), cfg.robot.radius)
    planner = CoveragePlanner(world, cfg, 3)
    spawns = {f"robot-{i}": (float(p[0]), float(p[1])) for i, p in enumerate(planner.spawns)}
    return planner, spawns


def _jittered(starts, seed):
    rng = np.random.default_rng(seed)
    return {r: (x + rng.normal(0, 0.002), y + rng.normal(0, 0.002)) for r, (x, y) in starts.items()}


def _same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(
        a[r].shape == b[r].shape and np.array_equal(a[r], b[r]) for r in a
    )


def test_millimetres_off_the_spawn_poses_give_the_plan_of_the_spawn_poses(small):
    planner, spawns = small
    # the planner alone is that sensitive: without the snap, 2 mm change the split
    raw = [
        plan_coverage(planner.grid, list(_jittered(spawns, s).values()), planner.params).paths
        for s in range(3)
    ]
    exact = plan_coverage(planner.grid, list(spawns.values()), planner.params).paths
    assert any(len(p) != len(q) for run in raw for p, q in zip(run, exact, strict=True))

    base = planner.plan(spawns)
    for seed in range(3):
        assert _same(planner.plan(_jittered(spawns, seed)), base)


def test_a_start_off_every_spawn_pose_is_planned_from_where_it_is(small):
    planner, spawns = small
    x, y = spawns["robot-0"]
    assert planner.snapped((x + 0.8 * SNAP_M, y)) == (x, y)
    assert planner.snapped((x + 1.2 * SNAP_M, y)) == (x + 1.2 * SNAP_M, y)
    moved = dict(spawns, **{"robot-0": (x + 0.2, y)})
    assert np.allclose(planner.plan(moved)["robot-0"][0], (x + 0.2, y))
