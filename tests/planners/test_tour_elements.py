"""The elements of a coverage tour: lanes, turns, other passes and hops, along its arc length."""

from __future__ import annotations

import numpy as np
import pytest

from planners.polyline import without_straight_vertices
from planners.tour_elements import (
    ELEMENT_KINDS,
    HOP,
    LANE,
    PASS,
    TURN,
    TourElements,
    locate,
    tour_elements,
)


def _pts(*xy: tuple[float, float]) -> np.ndarray:
    return np.array(xy, dtype=float)


def test_lanes_turns_passes_and_hops_in_driving_order() -> None:
    piece_a = _pts((0.0, 0.0), (1.0, 0.0))
    piece_b = _pts((1.0, 0.0), (2.0, 0.0))  # the same lane, cut in two
    group = _pts((2.0, 0.5), (0.0, 0.5), (0.0, 0.75), (2.0, 0.75))  # two lanes and a U-turn
    fill = _pts((2.5, 2.0), (2.5, 0.75))  # across the lanes: another pass
    # the tour as the planner joins them: hops between passes, straight runs merged
    tour = without_straight_vertices(np.vstack([piece_a, piece_b[1:], group, fill[::-1]]))
    el = tour_elements(tour, [[piece_a], [piece_b], [group], [fill, fill[::-1]]], [0.0] * 4)
    kinds = [ELEMENT_KINDS[k] for k in el.kind]
    assert kinds == ["lane", "lane", "hop", "lane", "turn", "lane", "hop", "pass"]
    assert el.run[0] == el.run[1], "two pieces of one lane are one run"
    assert len({el.run[3], el.run[5], el.run[0]}) == 3
    assert np.allclose(el.start_m, [0, 1, 2, 2.5, 4.5, 4.75, 6.75, 7.25])
    assert np.allclose(el.end_m[-1], 8.5)
    assert np.allclose(el.hop_m[el.kind == HOP], [0.5, 0.5])
    assert np.all(el.hop_m[el.kind != HOP] == 0)
    assert list(el.at(np.array([0.5, 2.2, 4.6, 8.0, 9.0]))) == [0, 2, 4, 7, -1]


def test_a_pass_mostly_across_its_rooms_lanes_is_one_pass_element() -> None:
    wall = _pts((0.0, 0.0), (0.0, 2.0), (0.3, 2.0))
    el = tour_elements(wall, [[wall]], [0.0])
    assert list(el.kind) == [PASS]
    el = tour_elements(wall, [[wall]], [np.pi / 2])
    assert list(el.kind) == [LANE, TURN]


def test_a_pass_not_on_the_tour_is_an_error() -> None:
    tour = _pts((0.0, 0.0), (2.0, 0.0))
    with pytest.raises(ValueError, match="pass 1 is not on the tour"):
        tour_elements(tour, [[tour], [_pts((0.0, 1.0), (1.0, 1.0))]], [0.0, 0.0])


def test_locate_finds_a_stretch_inside_segments_and_not_a_reversed_one() -> None:
    tour = _pts((0.0, 0.0), (2.0, 0.0), (2.0, 2.0))
    assert locate(tour, _pts((0.5, 0.0), (2.0, 0.0), (2.0, 1.0))) == pytest.approx(0.5)
    assert locate(tour, _pts((2.0, 1.0), (2.0, 0.0))) is None


def test_json_round_trip_and_errors_name_the_field() -> None:
    tour = _pts((0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0))
    el = tour_elements(tour, [[tour[:2]], [tour[2:]]], [0.0, 0.0])
    again = TourElements.from_json(el.to_json())
    assert np.array_equal(again.kind, el.kind) and np.allclose(again.end_m, el.end_m)
    bad = el.to_json()
    del bad["run"]
    with pytest.raises(ValueError, match="missing field run"):
        TourElements.from_json(bad)
    bad = el.to_json() | {"kind": [0, 9, 0]}
    with pytest.raises(ValueError, match="field kind"):
        TourElements.from_json(bad)
