"""A lane alone as pieces: they chain end to end over exactly the lane, none longer than
``max_lane_length``."""

from __future__ import annotations

import itertools

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

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


def _pieces(lanes: np.ndarray) -> list[list[tuple[float, float]]]:
    """Per lane, its pieces as (first, last) column, in the order of the lane."""
    width = int(lanes[:, 2].max()) + 1
    rows = int(lanes[:, 0].max()) + 2
    frame = RotatedFrame(0.0, (0.0, 0.0), RES, (rows, width))
    params = CoverageParams(overlap=1 / 6)
    tasks = cell_tasks(1, 1, lanes, frame, params, ROBOT)
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
@given(cell_lanes())
def test_pieces_chain_over_the_lane(lanes):
    params = CoverageParams()
    for (_, lo, hi), pieces in zip(lanes, _pieces(lanes), strict=True):
        pieces.sort()
        assert pieces[0][0] == lo and pieces[-1][1] == hi
        for (_, b), (a, _) in itertools.pairwise(pieces):
            assert a == b
        assert all((b - a) * RES <= params.max_lane_length + RES for a, b in pieces)


def test_a_long_lane_is_cut_in_equal_pieces_whatever_its_neighbour():
    # a 2.25 m lane beside a 1 m one ending at column 40: the pieces meet at 45
    lanes = np.array([(2.0, 0.0, 90.0), (12.0, 0.0, 40.0)])
    assert _pieces(lanes)[0] == [(0.0, 45.0), (45.0, 90.0)]
