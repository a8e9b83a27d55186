"""Grid tools: clearance, inflation, reachability and the cleanable area on hand-checked maps."""

import numpy as np
from coverage_maps import boxed, grid_of

from planners.grid import cleanable, clearance, disc, inflate, reachable


def test_clearance_is_distance_to_the_blocking_cell_edge():
    occ = np.zeros((5, 9), dtype=bool)
    occ[:, 0] = True
    g = grid_of(occ, res=0.1)
    # cell (2, 3) is 3 cells from the wall's centre: 2.5 cells from its edge; the grid border
    # (outside) blocks too, so the middle row is limited by top/bottom at 2.5 cells as well.
    assert np.isclose(clearance(g)[2, 3], 0.25)
    assert np.isclose(clearance(g)[2, 1], 0.05)


def test_inflate_blocks_cells_closer_than_the_radius():
    occ = boxed(20, 20)
    blocked = inflate(grid_of(occ), 0.17)
    # 0.17 m = 3.4 cells: cells whose centre is 4 cells from the wall cell are free (3.5 ≥ 3.4)
    assert blocked[3, 10] and not blocked[4, 10]
    assert blocked[10, 3] and not blocked[10, 4]


def test_disc_kernel_is_strict():
    k = disc(0.15, 0.05)
    assert k.shape == (7, 7)
    # offsets of exactly 3 cells (0.15 m) are outside; (2, 2) = 2.83 cells inside
    assert not k[3, 0] and k[3, 1] and k[1, 1] and k.sum() == 25


def test_reachable_and_cleanable_on_two_rooms():
    occ = boxed(30, 61)
    occ[:, 30] = True  # two closed rooms
    g = grid_of(occ)
    free = ~inflate(g, 0.17)
    reach = reachable(free, np.array([[15, 10]]))
    assert reach[15, 10] and not reach[15, 45]
    # walls at rows 0, 29 and columns 0, 30: centres 4 cells clear are rows 4..25, cols 4..26
    assert reach.sum() == 22 * 23
    clean = cleanable(g, reach, 0.15)
    # grown by 2 cells on every side: rows 2..27, cols 2..28
    assert clean.sum() == 26 * 27
    assert not clean[1, 10] and clean[2, 10] and not clean[:, 30:].any()
