"""SimGuard: a wait gives up on a stalled sim clock, never on a slow one, and never before its
wall bound."""

from __future__ import annotations

import pytest

from fleet.sim_guard import SimGuard


class Clocks:
    """A wall clock and a sim clock the test moves by hand."""

    def __init__(self) -> None:
        self.wall = 0.0
        self.sim = 0.0

    def guard(self, wall_s: float, stall_s: float, sim_s: float = float("inf")) -> SimGuard:
        return SimGuard(lambda: self.sim, wall_s, stall_s, sim_s, wall_now=lambda: self.wall)

    def run(self, guard: SimGuard, wall_s: float, rate: float, step: float = 1.0) -> float:
        """Move the wall clock ``step`` s at a time for ``wall_s``, the sim ``rate`` times as
        fast; the wall time at which the guard gave up, or inf if it did not."""
        end = self.wall + wall_s
        while self.wall < end:
            self.wall += step
            self.sim += rate * step
            if guard.expired():
                return self.wall
        return float("inf")


def test_a_slow_sim_clock_is_waited_for_past_the_wall_bound() -> None:
    """A starved run: the sim moves at 0.05x; a wall-only guard would give up at 60 s."""
    c = Clocks()
    guard = c.guard(wall_s=60.0, stall_s=10.0, sim_s=100.0)
    assert c.run(guard, 1000.0, 0.05) == float("inf")


def test_a_stalled_sim_clock_ends_the_wait_once_the_wall_bound_has_passed() -> None:
    c = Clocks()
    guard = c.guard(wall_s=60.0, stall_s=10.0)
    c.run(guard, 30.0, 1.0)  # moving for 30 s, then stopped
    assert c.run(guard, 1000.0, 0.0) == 60.0


def test_a_clock_that_stops_after_the_wall_bound_ends_the_wait_a_stall_later() -> None:
    c = Clocks()
    guard = c.guard(wall_s=60.0, stall_s=10.0)
    assert c.run(guard, 100.0, 1.0) == float("inf")
    assert c.run(guard, 1000.0, 0.0) == 110.0


def test_a_stalled_clock_does_not_end_the_wait_before_the_wall_bound() -> None:
    c = Clocks()
    guard = c.guard(wall_s=60.0, stall_s=10.0)
    assert c.run(guard, 59.0, 0.0) == float("inf")


def test_the_sim_budget_ends_a_wait_on_a_clock_that_keeps_moving() -> None:
    """Whatever was awaited did not happen in ``sim_s`` of sim time: given up, past the wall
    bound, when the sim has moved that far (here at 0.5x: 200 s wall)."""
    c = Clocks()
    guard = c.guard(wall_s=60.0, stall_s=10.0, sim_s=100.0)
    assert c.run(guard, 1000.0, 0.5) == 200.0


def test_a_fast_sim_does_not_end_the_wait_before_the_wall_bound() -> None:
    c = Clocks()
    guard = c.guard(wall_s=60.0, stall_s=10.0, sim_s=100.0)
    assert c.run(guard, 1000.0, 10.0) == 60.0


def test_why_names_the_wall_time_and_where_the_sim_clock_stopped() -> None:
    c = Clocks()
    guard = c.guard(wall_s=5.0, stall_s=2.0)
    c.run(guard, 3.0, 1.0)
    c.run(guard, 10.0, 0.0)
    assert "the sim clock at 3.0 s" in guard.why()


@pytest.mark.parametrize("args", [(-1.0, 1.0, 1.0), (1.0, 0.0, 1.0), (1.0, 1.0, 0.0)])
def test_bounds_that_make_no_sense_are_refused(args: tuple[float, float, float]) -> None:
    with pytest.raises(ValueError):
        SimGuard(lambda: 0.0, *args)
