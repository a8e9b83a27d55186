"""The robot's driving time over a path with stops: rest-to-rest runs and turns in place."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planners.drive_time import profile_time, time_into_run, vertex_times


def test_rest_to_rest_runs_are_trapezoids_or_triangles() -> None:
    # 0.5 m/s, 0.5 m/s²: a run needs 0.5 m to reach top speed and brake again
    assert profile_time(np.array(3.0), 0.5, 0.5) == pytest.approx(3.0 / 0.5 + 1.0)
    assert profile_time(np.array(0.27), 0.5, 0.5) == pytest.approx(2 * math.sqrt(0.27 / 0.5))
    assert profile_time(np.array(0.0), 0.5, 0.5) == 0.0
    # a turn in place by a quarter turn at 1 rad/s and 1 rad/s²
    assert profile_time(np.array(math.pi / 2), 1.0, 1.0) == pytest.approx(math.pi / 2 + 1.0)


def test_time_along_a_run_rises_to_its_whole_and_is_symmetric() -> None:
    for length in (0.3, 3.0):
        s = np.linspace(0.0, length, 101)
        t = time_into_run(s, length, 0.5, 0.5)
        total = float(profile_time(np.array(length), 0.5, 0.5))
        assert t[0] == 0.0 and t[-1] == pytest.approx(total)
        assert np.all(np.diff(t) > 0)
        # braking mirrors the speed-up
        np.testing.assert_allclose(t + t[::-1], total, atol=1e-9)


def test_a_lane_end_costs_two_stops_two_turns_and_a_short_hop() -> None:
    # along a 3 m lane, a 0.3 m hop up, back along the next lane
    pts = np.array([[0.0, 0.0], [1.5, 0.0], [3.0, 0.0], [3.0, 0.3], [0.0, 0.3]])
    stops = np.array([False, False, True, True, False])
    turns = np.array([0.0, 0.0, math.pi / 2, math.pi / 2, 0.0])
    t = vertex_times(pts, stops, turns, 0.5, 0.5, 1.0, 1.0)
    lane = 3.0 / 0.5 + 1.0
    quarter = math.pi / 2 + 1.0
    hop = 2 * math.sqrt(0.3 / 0.5)
    assert t[1] == pytest.approx(lane / 2)  # the vertex it drives through, at speed
    assert t[2] == pytest.approx(lane)
    assert t[3] == pytest.approx(lane + quarter + hop)
    assert t[4] == pytest.approx(2 * lane + 2 * quarter + hop)
    # a constant 0.5 m/s with nothing for stops would say 12.6 s
    assert t[4] > 6.3 / 0.5 + 6.0
