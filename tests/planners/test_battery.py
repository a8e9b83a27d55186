"""The battery model: what drains it, what charges it, when a robot stands on a dock, and the
market's energy check."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from robots import ROBOT

from fleet.config import ConfigError
from fleet.params import default_config_path, load_fleet_config
from planners.battery import (
    BatterySpec,
    DockUser,
    GoHome,
    can_take,
    charge_early,
    charge_per_s,
    docking_heading,
    drain_per_s,
    go_home_below,
    go_home_points,
    latest_leave_s,
    makespan_with_charging,
    on_dock,
    pick_dock,
    queue_wait_s,
    work_charge,
)

SPEC = BatterySpec(enabled=True, capacity_s=1000.0)


def _drain(v: float, w: float) -> float:
    rate = drain_per_s(SPEC, np.array([v]), np.array([w]), ROBOT.max_vel_x, ROBOT.wheel_base)
    return float(rate[0])


def test_sweeping_at_top_speed_lasts_capacity_s() -> None:
    assert _drain(ROBOT.max_vel_x, 0.0) == pytest.approx(1 / SPEC.capacity_s)


def test_standing_drains_the_electronics_only() -> None:
    assert _drain(0.0, 0.0) == pytest.approx(SPEC.idle_share / SPEC.capacity_s)


def test_half_speed_drains_half_the_wheels_share_and_the_whole_brush() -> None:
    share = SPEC.idle_share + SPEC.brush_share + SPEC.drive_share / 2
    assert _drain(ROBOT.max_vel_x / 2, 0.0) == pytest.approx(share / SPEC.capacity_s)


def test_a_turn_in_place_turns_the_wheels() -> None:
    assert _drain(0.0, 1.0) > _drain(0.0, 0.0) + SPEC.brush_share / SPEC.capacity_s


def test_a_dock_puts_back_charge_rate_seconds_of_sweeping_per_second() -> None:
    assert charge_per_s(SPEC) == pytest.approx(SPEC.charge_rate / SPEC.capacity_s)


def test_a_robot_is_on_a_dock_near_its_pose_and_facing_it() -> None:
    dock = (1.0, 0.5, math.pi / 2)  # the dock's body is to the south; a robot on it faces south
    assert docking_heading(dock) == pytest.approx(-math.pi / 2)
    poses = np.array(
        [
            [1.0, 0.5, -math.pi / 2],  # on it
            [1.05, 0.45, -math.pi / 2 + 0.3],  # within the tolerances
            [1.0, 0.5, math.pi / 2],  # backwards
            [1.0, 0.65, -math.pi / 2],  # too far
        ]
    )
    assert on_dock(SPEC, poses, dock).tolist() == [True, True, False, False]


def test_the_energy_check_refuses_work_it_cannot_finish_and_get_home_from() -> None:
    """Half a charge is 500 s of work at the sweeping drain: 400 s and 100 s home fit, 401 s
    do not."""
    assert can_take(SPEC, 0.5, 400.0, 100.0)
    assert not can_take(SPEC, 0.5, 401.0, 100.0)
    assert not can_take(SPEC, 0.5, 300.0, 201.0)


def test_without_batteries_any_work_is_taken() -> None:
    assert can_take(BatterySpec(enabled=False, capacity_s=1.0), 0.0, 1e6, 1e6)


def test_the_wait_at_a_dock_is_the_charging_of_each_robot_ahead() -> None:
    """charge_rate 4 on 1000 s: 250 s from 0 to a full charge. recharge_to 0.9: a robot at 0.1
    charges 200 s, one at 0.5 100 s; a robot above recharge_to adds nothing."""
    assert queue_wait_s(SPEC, []) == 0.0
    assert queue_wait_s(SPEC, [0.1]) == pytest.approx(200.0)
    assert queue_wait_s(SPEC, [0.1, 0.5, 0.95]) == pytest.approx(300.0)


def test_a_robot_goes_home_earlier_by_its_trip_and_its_wait_behind_the_queue() -> None:
    """Threshold 0.2; a 50 s trip at the sweeping drain is 0.05; 300 s waiting behind two
    robots at the electronics' drain (0.2 of it) is 0.06."""
    alone = go_home_below(SPEC, 0.0, [])
    assert alone == pytest.approx(0.2)
    assert go_home_below(SPEC, 50.0, []) == pytest.approx(0.25)
    assert go_home_below(SPEC, 50.0, [0.1, 0.5]) == pytest.approx(0.31)
    # the more robots ahead, the earlier it goes
    third = go_home_below(SPEC, 50.0, [0.1, 0.5, 0.3])
    assert third > go_home_below(SPEC, 50.0, [0.1, 0.5])
    assert go_home_below(BatterySpec(enabled=False), 50.0, [0.1]) == 0.0


SHORT = BatterySpec(enabled=True, capacity_s=300.0)  # threshold 0.2, to 0.9, rate 4


def test_the_makespan_without_a_charge_due_is_the_longest_work() -> None:
    assert makespan_with_charging(SHORT, [100.0, 200.0], [1.0, 1.0], 1) == 200.0
    off = BatterySpec(enabled=False, capacity_s=1.0)
    assert makespan_with_charging(off, [500.0], [0.0], 1) == 500.0


def test_the_makespan_counts_each_charge_a_robot_needs_on_the_way() -> None:
    """480 s of work on a 300 s charge: 240 s to the threshold, 52.5 s to charge 0.7 back,
    210 s more, a second charge, the last 30 s."""
    assert makespan_with_charging(SHORT, [480.0], [1.0], 1) == pytest.approx(585.0)


def test_robots_due_together_at_one_dock_charge_in_turn() -> None:
    """Two robots fall due at 240 s: the second waits the first's 52.5 s charge (0.035 of
    idle drain), charges 0.735 in 55.125 s and finishes its last 60 s after; with a dock each
    neither waits."""
    one = makespan_with_charging(SHORT, [300.0, 300.0], [1.0, 1.0], 1)
    assert one == pytest.approx(240.0 + 52.5 + 55.125 + 60.0)
    assert makespan_with_charging(SHORT, [300.0, 300.0], [1.0, 1.0], 2) == pytest.approx(352.5)


def test_the_makespan_counts_the_trips_to_the_dock_and_back_and_home() -> None:
    """480 s of work, 15 s from the dock: it leaves at 0.25 (the threshold and its trip) after
    225 s, arrives at 240 s, charges 52.5 s, is back at work at 307.5 s on 0.85, works 180 s to
    0.25 again, the same trip and charge (arrives 502.5 s, back at 570 s), its last 75 s of
    work and 15 s home: 660 s. Work that needs no charge ends with the trip home."""
    assert makespan_with_charging(SHORT, [480.0], [1.0], 1, [15.0]) == pytest.approx(660.0)
    assert makespan_with_charging(SHORT, [100.0], [1.0], 1, [15.0]) == pytest.approx(115.0)
    assert makespan_with_charging(SHORT, [480.0], [1.0], 1, [0.0]) == pytest.approx(585.0)


def test_a_robot_too_far_from_its_dock_to_work_between_charges_never_finishes() -> None:
    """110 s each way on a 300 s charge: charged to 0.9 it is back at its work on 0.53, already
    below the 0.57 it must leave at again."""
    assert makespan_with_charging(SHORT, [480.0], [1.0], 1, [110.0]) == math.inf


def _due(spec: BatterySpec, charge: float, trip_s: float) -> DockUser:
    return DockUser(charge, trip_s, (charge - go_home_below(spec, trip_s, [])) * spec.capacity_s)


def test_the_latest_leave_clears_the_dock_just_as_the_next_robot_falls_due() -> None:
    """Leaving at the latest leave, the robot drives there, charges to ``recharge_to`` from
    what it arrives with, and is off the dock at ``free_by_s`` exactly; never after its own
    go-home point."""
    robot = _due(SHORT, 0.7, 20.0)
    leave = latest_leave_s(SHORT, robot, 150.0)
    arrival = robot.charge - work_charge(SHORT, leave + robot.trip_s)
    off = leave + robot.trip_s + (SHORT.recharge_to - arrival) / charge_per_s(SHORT)
    assert 0.0 < leave < robot.due_s and off == pytest.approx(150.0)
    assert latest_leave_s(SHORT, robot, 1e6) == robot.due_s


def test_robots_falling_due_together_are_sent_one_by_one_before_their_go_home_point() -> None:
    """Three robots 25 s from the one dock, 0.01 apart: full, none is sent; run down to about
    0.6, the lowest goes (before its go-home point at 0.28), so that each charge is over
    before the next robot falls due, instead of the three queueing at the same moment."""

    def three(c: float) -> list[DockUser]:
        return [_due(SHORT, c + d, 25.0) for d in (0.02, 0.0, 0.01)]

    assert charge_early(SHORT, three(0.9)) is None
    assert charge_early(SHORT, three(0.75)) is None
    assert charge_early(SHORT, three(0.6)) == 1  # the lowest, wherever it is listed
    assert three(0.6)[1].due_s > 0  # not yet at its go-home point


def test_no_robot_is_sent_early_alone_full_far_apart_or_without_batteries() -> None:
    low = _due(SHORT, 0.35, 25.0)
    assert charge_early(SHORT, [low]) is None  # a dock to itself: its go-home point is enough
    assert charge_early(SHORT, [low, _due(SHORT, 0.95, 25.0)]) is None  # the next is far off
    full = DockUser(0.9, 25.0, 5.0)
    assert charge_early(SHORT, [full, _due(SHORT, 0.35, 25.0)]) is None  # nothing to charge
    off = BatterySpec(enabled=False, capacity_s=300.0)
    assert charge_early(off, [low, low]) is None


def _config_error(tmp_path: Path, **battery: object) -> str:
    data = yaml.safe_load(default_config_path().read_text())
    data["robot"]["battery"].update(battery)
    path = tmp_path / "fleet.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError) as info:
        load_fleet_config(path)
    return str(info.value)


def test_the_config_names_the_battery_field_it_refuses(tmp_path: Path) -> None:
    assert "robot.battery: capacity_s must be > 0" in _config_error(tmp_path, capacity_s=0)
    msg = _config_error(tmp_path, drive_share=0.9)
    assert "robot.battery: drive_share + brush_share + idle_share must add up to 1" in msg
    msg = _config_error(tmp_path, recharge_to=0.1)
    assert "robot.battery: recharge_to (0.1) must be in (recharge_threshold, 1]" in msg


def test_batteries_are_off_by_default() -> None:
    assert not load_fleet_config().robot.battery.enabled


CORRIDOR = BatterySpec(enabled=True, capacity_s=120.0)


def test_pick_dock_waits_by_the_near_dock_when_that_is_sooner_than_crossing() -> None:
    """Near dock 5 s away with a robot ahead charging from 0.25 (about 20 s), far dock 40 s
    away and free: the near one is on soonest; with two robots ahead (about 40 s) the far one
    is, if the charge covers the trip; with a charge covering neither, the one needing least."""
    one, two = [0.25], [0.25, 0.25]
    assert pick_dock(CORRIDOR, 0.8, (5.0, 40.0), [one, []]) == 0
    assert pick_dock(CORRIDOR, 0.8, (5.0, 40.0), [[*two, 0.25], []]) == 1
    need_far = go_home_below(CORRIDOR, 40.0, [])
    need_near = go_home_below(CORRIDOR, 5.0, [*two, 0.25])
    assert need_near < need_far  # waiting costs less charge than the trip across
    assert pick_dock(CORRIDOR, (need_near + need_far) / 2, (5.0, 40.0), [[*two, 0.25], []]) == 0
    assert pick_dock(CORRIDOR, 0.1, (5.0, math.inf), [[], []]) == 0
    assert pick_dock(CORRIDOR, 0.8, (math.inf, math.inf), [[], []]) is None


def test_two_robots_falling_due_together_by_one_dock_count_each_other() -> None:
    """Robots 0 and 1, 5 s and 8 s from dock 0 (dock 1 40 s off), fall due together: each
    point holds the wait behind the other charging from the threshold at dock 0 (less than the
    trip across), whichever the docks take first; robot 0, the nearer to its point, goes first.
    A robot due long after the other has charged and left counts no one."""
    spec = CORRIDOR
    alone0 = go_home_below(spec, 5.0, [])
    alone1 = go_home_below(spec, 8.0, [])
    robots = [GoHome(alone0 - 0.001, (5.0, 40.0)), GoHome(alone1, (8.0, 40.0))]
    out = go_home_points(spec, robots, [[], []])
    assert [i for i, _, _ in out] == [0, 1]
    behind0 = go_home_below(spec, 5.0, [spec.recharge_threshold])
    behind1 = go_home_below(spec, 8.0, [spec.recharge_threshold])
    assert behind1 < go_home_below(spec, 40.0, [])
    assert out[0][1:] == (0, pytest.approx(behind0))
    assert out[1][1:] == (0, pytest.approx(behind1))
    late = GoHome(0.95, (8.0, 40.0))  # 0.7 of a charge (84 s) from due: robot 0 is long gone
    out = go_home_points(spec, [robots[0], late], [[], []])
    assert out[0][1:] == (0, pytest.approx(alone0))
    assert out[1][1:] == (0, pytest.approx(alone1))
    off = BatterySpec(enabled=False)
    assert go_home_points(off, robots, [[], []]) == [(0, None, 0.0), (1, None, 0.0)]


def test_a_robot_that_counting_the_other_makes_due_first_is_counted_by_it() -> None:
    """Robot 0 is 0.02 above its point alone, robot 1 0.03 above: counting robot 0 ahead of
    it (0.035 at the idle drain) puts robot 1 below its point before robot 0 reaches its
    point alone, so robot 0's point must count robot 1 too (one pass in the order they fall due
    alone would leave robot 0 on its point alone): they count each other."""
    spec = CORRIDOR
    alone0 = go_home_below(spec, 5.0, [])
    alone1 = go_home_below(spec, 8.0, [])
    robots = [GoHome(alone0 + 0.02, (5.0, 40.0)), GoHome(alone1 + 0.03, (8.0, 40.0))]
    out = dict((i, (k, p)) for i, k, p in go_home_points(spec, robots, [[], []]))
    assert out[1] == (0, pytest.approx(go_home_below(spec, 8.0, [spec.recharge_threshold])))
    assert out[0] == (0, pytest.approx(go_home_below(spec, 5.0, [spec.recharge_threshold])))


def test_a_robot_whose_near_dock_is_held_long_counts_the_trip_across() -> None:
    """Two robots already bound for dock 0 and one falling due before it there: waiting would
    cost more charge (0.155 over the threshold and its 6 s trip) than the 10 s trip to dock 1,
    so its point is the trip across."""
    spec = CORRIDOR
    robots = [GoHome(0.3, (5.0, 40.0)), GoHome(0.5, (6.0, 10.0))]
    out = go_home_points(spec, robots, [[0.2, 0.2], []])
    assert out[1][1:] == (1, pytest.approx(go_home_below(spec, 10.0, [])))
