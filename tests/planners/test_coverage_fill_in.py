"""Which fill-in passes are taken when only part of the missed floor is needed."""

import numpy as np
from coverage_maps import boxed, grid_of

from planners.coverage.fill_in import fill_in_tasks
from planners.coverage.transit import Transit
from planners.grid import cleanable, clearance, reachable


def test_the_last_pass_needed_is_the_cheapest_one_that_reaches_the_target():
    g = grid_of(boxed(60, 90))
    reach = reachable(clearance(g) >= 0.17, g.world_to_cell(np.array([[0.5, 1.0]])))
    clean = cleanable(g, reach, 0.15)
    covered = clean.copy()
    # a big patch 0.4 m from the path (the most cells per metre) and a small one beside it
    covered[28:34, 40:46] = False
    covered[10:12, 20:23] = False
    anchors = g.cell_to_world(np.array([[31.0, 54.0], [11.0, 24.0]]))
    missing = int((clean & ~covered).sum())
    target = 1.0 - (missing - 5) / clean.sum()
    passes = fill_in_tasks(g, covered, anchors, clean, reach, 0.15, Transit(g, reach), target)
    assert len(passes) == 1
    path, area = passes[0]
    assert area == 6 * g.resolution**2
    assert np.hypot(*(path - anchors[1]).T).max() < 0.3
