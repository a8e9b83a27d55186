"""Lanes in continuous coordinates: exact spacing, no lattice lane left out, robot-centre cells
only."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from planners.coverage.bcd import decompose
from planners.coverage.lattice import room_lanes
from planners.grid import dilate


@st.composite
def rooms(draw) -> tuple[np.ndarray, float, float, float]:
    """A room on a grid: a row-monotone polygon (one run of columns per row, each run touching
    the one below), sometimes with a box of furniture inside (then several cells), and a brush
    width, lane overlap and resolution."""
    rows = draw(st.integers(2, 60))
    lo = [draw(st.integers(0, 8))]
    hi = [lo[0] + draw(st.integers(0, 50))]
    for _ in range(rows - 1):
        a = max(0, lo[-1] + draw(st.integers(-3, 3)))
        b = hi[-1] + draw(st.integers(-3, 3))
        a, b = min(a, hi[-1]), max(b, lo[-1])
        lo.append(min(a, b))
        hi.append(max(a, b))
    res = draw(st.sampled_from([0.025, 0.05]))
    width = draw(st.floats(0.15, 0.5))
    overlap = draw(st.floats(0.0, 0.5))
    pad = math.ceil(width / 2 / res) + 2
    mask = np.zeros((rows + 2 * pad, max(hi) + 1 + 2 * pad), dtype=bool)
    for r, (a, b) in enumerate(zip(lo, hi, strict=True)):
        mask[pad + r, pad + a : pad + b + 1] = True
    if draw(st.booleans()) and rows >= 8:
        r0 = pad + draw(st.integers(2, rows - 6))
        c0 = pad + draw(st.integers(0, max(hi)))
        mask[r0 : r0 + draw(st.integers(1, 4)), c0 : c0 + draw(st.integers(1, 6))] = False
    return mask, width, overlap, res


def _place(mask: np.ndarray, width: float, overlap: float, res: float):
    labels, cells = decompose(mask, max_step=max(mask.shape))
    hw = width / 2 / res
    clean = dilate(mask, hw, 1.0)
    placed = room_lanes(cells, mask, clean, labels, width * (1 - overlap) / res, hw)
    return cells, placed


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(rooms())
def test_lattice_lanes_are_spacing_apart_and_on_robot_centre_cells(room):
    mask, width, overlap, res = room
    cells, placed = _place(mask, width, overlap, res)
    spacing_m = width * (1 - overlap)
    for lattice in placed.lattice:
        # adjacent lattice lanes of every cell: the spacing apart, to a millimetre
        gaps_m = np.diff(lattice[:, 0]) * res
        assert np.all(np.abs(gaps_m - spacing_m) < 1e-3), (gaps_m, spacing_m)
    if len(cells) == 1 and len(placed.lattice[0]) and cells[0].rows > 1:
        # one cell: no room for another lattice lane between its first or last row and the
        # lattice (what is left along the walls is narrower than the spacing)
        cell, ys = cells[0], placed.lattice[0][:, 0]
        spacing = spacing_m / res
        assert ys[0] - cell.row0 < spacing + 1e-6
        assert cell.row0 + cell.rows - 1 - ys[-1] < spacing + 1e-6
    for lanes in (*placed.lattice, *placed.clamps, *placed.shoulders):
        for y, lo, hi in lanes:
            # every point of the lane lies between two robot-centre cells of its columns
            for r in {math.floor(y), math.ceil(y)}:
                assert mask[r, int(lo) : int(hi) + 1].all(), (y, lo, hi)
