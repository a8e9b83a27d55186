"""Scoring an explored map against the true floor, and the robots' path lengths."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fleet.coordinator.store import JobStore
from fleet.report.exploration import (
    free_iou,
    growth,
    mapped_free_on,
    path_lengths,
    plan_floor_lost,
    true_floor,
    walls_within,
)
from fleet.world import load_world
from planners.grid import GridMap

SMALL = Path(__file__).resolve().parents[2] / "configs" / "worlds" / "small.yaml"


def test_the_true_floor_is_the_free_space_a_robot_start_reaches(tmp_path: Path):
    truth, floor = true_floor(load_world(SMALL), 0.05, (0.6, 0.85))
    # 4 m × 3 m inside 10 cm walls, less the 0.8 m × 0.6 m table and the dock
    assert 9.5 < floor.sum() * 0.05**2 < 11.3
    assert not (floor & truth.occupied).any()
    # a closet walled in on every side is no floor
    closet = tmp_path / "closet.yaml"
    walls = "  - [3.0, 2.0, 3.8, 2.0]\n  - [3.8, 2.0, 3.8, 2.8]\n"
    walls += "  - [3.8, 2.8, 3.0, 2.8]\n  - [3.0, 2.8, 3.0, 2.0]\n"
    closet.write_text(SMALL.read_text().replace("walls:\n", "walls:\n" + walls))
    truth, walled = true_floor(load_world(closet), 0.05, (0.6, 0.85))
    inside = truth.world_to_cell(np.array([[3.4, 2.4]]))[0]
    assert truth.free[inside[0], inside[1]] and not walled[inside[0], inside[1]]


def test_the_floor_mapped_exactly_scores_one_and_half_of_it_about_a_half():
    truth, floor = true_floor(load_world(SMALL), 0.05, (0.6, 0.85))
    # the map on a grid of its own, offset by a quarter cell: each true cell finds its own
    shifted = GridMap(
        truth.occupied, ~floor & ~truth.occupied, 0.05, (truth.origin[0] - 0.0125, truth.origin[1])
    )
    assert np.array_equal(mapped_free_on(shifted, truth), floor)
    assert free_iou(shifted, truth, floor) == pytest.approx(1.0)
    half = floor.copy()
    half[:, half.shape[1] // 2 :] = False
    mapped = GridMap(truth.occupied, ~half & ~truth.occupied, 0.05, truth.origin)
    assert free_iou(mapped, truth, floor) == pytest.approx(half.sum() / floor.sum())
    everything = GridMap(truth.occupied & False, truth.occupied & False, 0.05, truth.origin)
    assert free_iou(everything, truth, floor) == pytest.approx(floor.sum() / floor.size)
    nothing = GridMap(np.zeros((2, 2), bool), np.ones((2, 2), bool), 0.05, (50.0, 50.0))
    assert free_iou(nothing, truth, floor) == 0.0


def test_path_lengths_sum_each_robots_track():
    tracks = {"robot-1": [(0.0, 0.0, 0.0), (1.0, 3.0, 4.0), (2.0, 3.0, 5.0)], "robot-0": []}
    assert path_lengths(tracks) == {"robot-0": 0.0, "robot-1": 6.0}


def test_walls_within_5_cm_count_a_wall_a_cell_off_and_not_two():
    truth, floor = true_floor(load_world(SMALL), 0.05, (0.6, 0.85))
    assert walls_within(truth, truth, floor) == pytest.approx(1.0)
    # the whole map one cell (5 cm) off still finds every wall; two cells (10 cm) off, the
    # walls facing the shift are lost (the wall is two cells thick, so some remain found)
    x0, y0 = truth.origin
    one_off = GridMap(truth.occupied, truth.unknown, 0.05, (x0 + 0.05, y0))
    assert walls_within(one_off, truth, floor) == pytest.approx(1.0)
    far = GridMap(truth.occupied, truth.unknown, 0.05, (x0 + 0.3, y0))
    assert walls_within(far, truth, floor) < 0.8
    # half the walls mapped: about half found
    half = truth.occupied.copy()
    half[:, half.shape[1] // 2 :] = False
    share = walls_within(GridMap(half, truth.unknown, 0.05, truth.origin), truth, floor)
    assert 0.3 < share < 0.7
    nothing = GridMap(np.zeros_like(half), truth.unknown, 0.05, truth.origin)
    assert walls_within(nothing, truth, floor) == 0.0


def test_the_floor_a_plan_on_the_map_loses_is_told_by_cause():
    world = load_world(SMALL)
    truth = world.grid(0.025)
    dock = (0.6, 0.85)

    def lost(mapped: GridMap) -> dict[str, float]:
        return plan_floor_lost(mapped, world, dock, 0.185, 0.15)

    exact = lost(truth)
    assert exact["lost_m2"] == 0.0 and 8.0 < exact["brushable_m2"] < 11.0
    # the south wall drawn 5 cm onto the floor: a strip of floor lost to it, nothing else
    rows = truth.world_to_cell(np.array([[2.0, 0.06], [2.0, 0.09]]))[:, 0]
    thick = truth.occupied.copy()
    thick[rows[0] : rows[1] + 1, :] |= truth.free[rows[0] : rows[1] + 1, :]
    walls = lost(GridMap(thick, truth.unknown, truth.resolution, truth.origin))
    assert 0.1 < walls["lost_m2"] == walls["walls_on_floor_m2"] == walls["both_m2"]
    assert walls["unknown_on_floor_m2"] == 0.0
    # the north-east corner's floor left unknown: lost to unknown, not to walls
    xy = truth.cell_to_world(np.argwhere(truth.free))
    corner = np.zeros(truth.shape, dtype=bool)
    rc = np.argwhere(truth.free)[(xy[:, 0] > 3.7) & (xy[:, 1] > 2.7)]
    corner[rc[:, 0], rc[:, 1]] = True
    unknown = lost(GridMap(truth.occupied, corner, truth.resolution, truth.origin))
    assert 0.0 < unknown["lost_m2"] == unknown["unknown_on_floor_m2"]
    assert unknown["walls_on_floor_m2"] == 0.0


def test_the_growth_lists_each_update_that_changed_the_merged_map(tmp_path: Path):
    store = JobStore(tmp_path / "coordinator.sqlite")
    details = [
        (1.9, "known 0.0 m², 0 frontiers, 0 new, 0 gone; goals: none"),
        (4.0, "known 13.4 m², 10 frontiers, 10 new, 0 gone; goals: robot-0 → f001 (2.8, 0.8)"),
        (6.0, "known 13.4 m², 10 frontiers, 0 new, 0 gone; goals: robot-0 → f001 (2.8, 0.8)"),
        (8.1, "known 17.3 m², 11 frontiers, 6 new, 4 gone; goals: none"),
    ]
    for sim, detail in details:
        store.add_event(0.0, sim, "explored", "", "", detail)
    store.add_event(0.0, 9.0, "awarded", "robot-0", "f002", "f002: 3.1 s")
    store.close()
    assert growth(tmp_path / "coordinator.sqlite") == [
        [1.9, 0.0, 0],
        [4.0, 13.4, 10],
        [8.1, 17.3, 11],
    ]
