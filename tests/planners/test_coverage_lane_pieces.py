"""A lane alone as pieces: they chain end to end over exactly the lane, none longer than
``max_lane_length``, and with ``neighbour_cuts`` one ends wherever another lane of the cell
ends well inside it."""

from __future__ import annotations

import itertools

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from planners.coverage.bcd import MonotoneCell
from planners.coverage.frame import RotatedFrame
from planners.coverage.params import CoverageParams
from planners.coverage.tasks import cell_tasks
from planners.robot import RobotSpec

RES = 0.025
ROBOT = RobotSpec(
    radius=0.17,
    wheel_base=0.23,
    cleaning_width=0.3,
    max_vel_x=0.5,
    max_vel_theta=2.0,
    acc_lim_x=1.0,
    acc_lim_theta=3.0,
    mass=3.0,
)


def _pieces(lanes: np.ndarray, cuts: bool) -> list[list[tuple[float, float]]]:
    """Per lane, its pieces as (first, last) column, in the order of the lane."""
    width = int(lanes[:, 2].max()) + 1
    rows = int(lanes[:, 0].max()) + 2
    cell = MonotoneCell(0, np.zeros(rows, dtype=int), np.full(rows, width - 1))
    frame = RotatedFrame(0.0, (0.0, 0.0), RES, (rows, width))
    params = CoverageParams(overlap=1 / 6, neighbour_cuts=cuts)
    tasks = cell_tasks(1, 1, cell, lanes, frame, params, ROBOT, max_area=0.0)
    out: list[list[tuple[float, float]]] = [[] for _ in lanes]
    for t in tasks:
        (x0, y0), (x1, _) = t.variants[0]
        k = int(np.argmin(np.abs(lanes[:, 0] * RES - y0)))
        out[k].append((round(x0 / RES, 6), round(x1 / RES, 6)))
    return out


@st.composite
def cell_lanes(draw) -> np.ndarray:
    """Lanes 10 rows apart, each spanning its own columns."""
    n = draw(st.integers(2, 8))
    spans = []
    for _ in range(n):
        lo = draw(st.integers(0, 80))
        spans.append((lo, lo + draw(st.integers(0, 200))))
    return np.array([(2.0 + 10 * k, lo, hi) for k, (lo, hi) in enumerate(spans)], dtype=float)


@settings(max_examples=200, deadline=None)
@given(cell_lanes(), st.booleans())
def test_pieces_chain_over_the_lane_and_end_at_neighbour_ends(lanes, cuts):
    params = CoverageParams()
    margin = params.max_lane_length / 4 / RES
    for (_, lo, hi), pieces in zip(lanes, _pieces(lanes, cuts), strict=True):
        pieces.sort()
        assert pieces[0][0] == lo and pieces[-1][1] == hi
        for (_, b), (a, _) in itertools.pairwise(pieces):
            assert a == b
        assert all((b - a) * RES <= params.max_lane_length + RES for a, b in pieces)
        bounds = {b for _, b in pieces[:-1]}
        inside = {c for c in lanes[:, 1:3].ravel() if lo + margin < c < hi - margin}
        if cuts:
            assert inside <= bounds


def test_a_long_lane_is_cut_where_its_neighbour_ends_only_when_asked():
    # a 2.25 m lane beside a 1 m one ending at column 40: plain pieces meet at 45
    lanes = np.array([(2.0, 0.0, 90.0), (12.0, 0.0, 40.0)])
    assert _pieces(lanes, False)[0] == [(0.0, 45.0), (45.0, 90.0)]
    assert _pieces(lanes, True)[0] == [(0.0, 40.0), (40.0, 90.0)]
