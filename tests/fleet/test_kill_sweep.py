"""The kill sweep's own arithmetic (fleet.bench.kill_sweep); the runs are real fleets."""

from __future__ import annotations

import numpy as np

from fleet.bench.kill_sweep import body_mask, sweep_lines


def test_the_body_mask_holds_the_cells_under_the_body() -> None:
    visits = np.zeros((20, 30))
    mask = body_mask(visits, 0.05, (0.0, 0.0), (0.5, 0.5), 0.17)
    assert mask.shape == visits.shape
    # cell centres within 0.17 m of (0.5, 0.5): about pi * 0.17² / 0.05² cells
    assert abs(mask.sum() - np.pi * 0.17**2 / 0.05**2) < 8
    rows, cols = np.nonzero(mask)
    assert abs(cols.mean() * 0.05 + 0.025 - 0.5) < 0.03
    assert abs(rows.mean() * 0.05 + 0.025 - 0.5) < 0.03


def test_the_table_has_a_row_per_moment() -> None:
    row = {
        "kill_sim_s": 10.8,
        "status": "incomplete",
        "coverage": 0.9,
        "coverage_outside_body": 0.95,
        "makespan_ratio": 1.2,
        "contacts": {"robot_wall": 0, "robot_robot": 1},
        "given_up": 3,
        "escape_s": 12.5,
        "stuck_events": 1,
    }
    lines = sweep_lines([row, {**row, "kill_sim_s": 20.0}])
    assert len(lines) == 3
    assert "incomplete" in lines[1] and "0/1" in lines[1] and "20.0" in lines[2]
