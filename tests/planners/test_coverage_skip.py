"""The skip order of a lane group (Fields2Cover's snake): the same lanes as the plain
boustrophedon, each once, ending beside the lane it began on, turns inside the cell."""

from __future__ import annotations

import itertools
import math

import numpy as np
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from planners.coverage.bcd import MonotoneCell, decompose
from planners.coverage.frame import RotatedFrame
from planners.coverage.lattice import room_lanes
from planners.coverage.params import CoverageParams
from planners.coverage.sweeps import boustrophedon, skip_order
from planners.coverage.tasks import cell_tasks
from planners.grid import dilate
from planners.robot import RobotSpec


@st.composite
def cells_with_lanes(draw) -> tuple[MonotoneCell, np.ndarray, float]:
    """A row-monotone room on a 2.5 cm grid, one of its cells with three lanes or more, and
    the lane spacing in rows."""
    rows = draw(st.integers(12, 50))
    lo = [draw(st.integers(0, 8))]
    hi = [lo[0] + draw(st.integers(4, 40))]
    for _ in range(rows - 1):
        a = max(0, lo[-1] + draw(st.integers(-3, 3)))
        b = hi[-1] + draw(st.integers(-3, 3))
        a, b = min(a, hi[-1] - 1), max(b, lo[-1] + 1)
        lo.append(min(a, b))
        hi.append(max(a, b))
    width = draw(st.floats(0.15, 0.4))
    overlap = draw(st.floats(0.0, 0.3))
    hw = width / 2 / 0.025
    pad = math.ceil(hw) + 2
    mask = np.zeros((rows + 2 * pad, max(hi) + 1 + 2 * pad), dtype=bool)
    for r, (a, b) in enumerate(zip(lo, hi, strict=True)):
        mask[pad + r, pad + a : pad + b + 1] = True
    labels, cells = decompose(mask, max_step=max(mask.shape))
    spacing = width * (1 - overlap) / 0.025
    placed = room_lanes(cells, mask, dilate(mask, hw, 1.0), labels, spacing, hw)
    found = [(c, ln) for c, ln in zip(cells, placed.lanes(), strict=True) if len(ln) >= 3]
    assume(found)
    cell, lanes = found[draw(st.integers(0, len(found) - 1))]
    return cell, lanes, spacing


def _driven_lanes(path: np.ndarray, lanes: np.ndarray) -> list[int]:
    """Index of the lane each segment of ``path`` drives whole (along its row, end to end),
    and of each lane one cell long (a point) the path passes."""
    out = []
    for (y0, c0), (y1, c1) in itertools.pairwise(path):
        for k, (y, lo, hi) in enumerate(lanes):
            if lo < hi and y0 == y1 == y and {c0, c1} == {lo, hi}:
                out.append(k)
    for k, (y, lo, hi) in enumerate(lanes):
        if lo == hi and any(np.array_equal(p, (y, lo)) for p in path):
            out.append(k)
    return out


def _inside(cell: MonotoneCell, path: np.ndarray) -> bool:
    """Every vertex of ``path`` on the cell: its row's span (both rows beside a lane row)."""
    for y, c in path:
        for r in {math.floor(y), math.ceil(y)}:
            k = r - cell.row0
            if not (0 <= k < cell.rows and cell.left[k] <= c <= cell.right[k]):
                return False
    return True


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cells_with_lanes(), st.booleans())
def test_skip_order_sweeps_the_plain_lanes_and_ends_beside_its_first(case, left_first):
    cell, lanes, spacing = case
    n = len(lanes)
    plain = boustrophedon(cell, lanes, left_first)
    skip = boustrophedon(cell, lanes[skip_order(n)], left_first)
    assert sorted(_driven_lanes(skip, lanes)) == sorted(_driven_lanes(plain, lanes))
    assert sorted(_driven_lanes(skip, lanes)) == list(range(n))
    assert _inside(cell, skip)
    # it begins where the plain run begins and ends on the lane beside its first one
    assert np.array_equal(skip[0], plain[0])
    assert skip[-1][0] == lanes[1][0]
    assert abs(skip[-1][0] - skip[0][0]) <= spacing + 1e-9
    # with an even count on the very end it began at, as a plain run ends only with an odd
    # count's far lane
    if n % 2 == 0:
        assert skip[-1][1] == (lanes[1][1] if left_first else lanes[1][2])


def test_skip_order_is_out_on_every_other_lane_and_back_on_the_rest():
    assert skip_order(3).tolist() == [0, 2, 1]
    assert skip_order(6).tolist() == [0, 2, 4, 5, 3, 1]
    assert skip_order(7).tolist() == [0, 2, 4, 6, 5, 3, 1]


def _robot() -> RobotSpec:
    return RobotSpec(
        radius=0.17,
        wheel_base=0.23,
        cleaning_width=0.3,
        max_vel_x=0.5,
        max_vel_theta=2.0,
        acc_lim_x=1.0,
        acc_lim_theta=3.0,
        mass=3.0,
    )


def test_a_lane_group_gets_the_skip_variants_only_when_asked():
    cell = MonotoneCell(0, np.zeros(40, dtype=int), np.full(40, 60))
    lanes = np.array([(2.0 + 10 * k, 0.0, 60.0) for k in range(4)])
    frame = RotatedFrame(0.0, (0.0, 0.0), 0.025, (40, 61))
    robot = _robot()
    for skip, count in ((False, 2), (True, 4)):
        params = CoverageParams(overlap=1 / 6, skip_order=skip)
        (task,) = cell_tasks(1, 1, cell, lanes, frame, params, robot, max_area=100.0)
        assert len(task.variants) == count
    plain, _, snake, _ = task.variants
    # the skip variant leaves at the start's end of the group, one spacing across from it
    assert np.allclose(snake[0], plain[0])
    assert np.allclose(snake[-1], [0.0, 0.25 + 0.05])
    assert np.allclose(plain[-1], [0.0, 0.75 + 0.05])
