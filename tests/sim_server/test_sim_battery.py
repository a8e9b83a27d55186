"""Batteries in the simulator: driving drains them, a robot at 0 % stands, a dock charges the
one robot on it, and with batteries off nothing changes."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from fleet.config import ConfigError, configs_dir
from fleet.params import FleetConfig, load_fleet_config
from fleet.report.summary import battery_of
from fleet.world import World, load_world
from sim_server.core import SimCore


@pytest.fixture(scope="module")
def world() -> World:
    return load_world(configs_dir() / "worlds" / "small.yaml")


def _cfg(**battery: object) -> FleetConfig:
    cfg = load_fleet_config()
    spec = dataclasses.replace(cfg.robot.battery, enabled=True, **battery)
    return dataclasses.replace(cfg, robot=dataclasses.replace(cfg.robot, battery=spec))


def _run(sim: SimCore, seconds: float) -> list:
    out = []
    for _ in range(round(seconds / sim.dt)):
        out += sim.step().batteries
    return out


def _charge(sim: SimCore, rid: str) -> float:
    s = sim.summary(0.0)
    return float(s.charge[s.robots.index(rid)])


def test_driving_drains_more_than_standing(world: World) -> None:
    sim = SimCore(world, _cfg(capacity_s=100.0))
    sim.add_robot("a", (1.0, 2.3, 0.0))
    sim.add_robot("b", (1.0, 1.0, 0.0))
    sim.set_cmd("a", 0.3, 0.0)
    readings = _run(sim, 4.0)
    a, b = _charge(sim, "a"), _charge(sim, "b")
    assert b == pytest.approx(1 - 4.0 * 0.2 / 100.0, abs=1e-3)
    assert a < b - 0.01
    # the sensor reads it on the robot's own key, twice a second
    mine = [m for rid, m in readings if rid == "a"]
    assert len(mine) == 8 and mine[-1].percentage == pytest.approx(a, abs=1e-3)


def test_a_robot_at_zero_stands_whatever_it_is_told(world: World) -> None:
    sim = SimCore(world, _cfg(capacity_s=2.0))
    sim.add_robot("a", (1.0, 2.3, 0.0))
    sim.set_cmd("a", 0.5, 0.0)
    _run(sim, 4.0)  # runs out within 2 s
    assert _charge(sim, "a") == 0.0
    x0 = sim.truth()["a"][0]
    sim.set_cmd("a", 0.5, 0.0)
    _run(sim, 2.0)
    assert sim.truth()["a"][0] == pytest.approx(x0, abs=1e-3)
    assert float(sim.summary(0.0).min_charge[0]) == 0.0


def test_the_dock_charges_the_robot_standing_on_it(world: World) -> None:
    dock = world.dock
    assert dock is not None
    sim = SimCore(world, _cfg(capacity_s=100.0))
    facing = dock[2] + math.pi
    sim.add_robot("on", (dock[0], dock[1], facing))
    sim.add_robot("off", (dock[0] + 1.0, dock[1] + 0.5, facing))
    _run(sim, 5.0)
    s = sim.summary(0.0)
    on, off = s.robots.index("on"), s.robots.index("off")
    assert s.charge[on] == 1.0 and s.docked[on] == 1 and s.charges[on] == 1
    assert s.charging_s[on] == pytest.approx(5.0, abs=0.02)
    assert s.charge[off] < 1.0 and s.docked[off] == 0 and s.charges[off] == 0


def test_a_robot_backed_onto_the_dock_does_not_charge(world: World) -> None:
    dock = world.dock
    assert dock is not None
    sim = SimCore(world, _cfg(capacity_s=100.0))
    sim.add_robot("a", (dock[0], dock[1], dock[2]))
    _run(sim, 1.0)
    assert sim.summary(0.0).docked.tolist() == [0]


def test_with_batteries_off_nothing_drains_and_nothing_is_sent(world: World) -> None:
    cfg = load_fleet_config()
    assert not cfg.robot.battery.enabled
    sim = SimCore(world, cfg)
    sim.add_robot("a", (1.0, 2.3, 0.0))
    sim.set_cmd("a", 0.5, 0.0)
    assert _run(sim, 2.0) == []
    s = sim.summary(0.0)
    assert len(s.charge) == 0 and len(s.docked) == 0


def test_batteries_change_no_motion_until_one_runs_out(world: World) -> None:
    """Bit for bit: the same seed drives the same way with batteries on as off, while charge
    lasts (the battery takes nothing from the random stream)."""
    runs = []
    for cfg in (load_fleet_config(), _cfg(capacity_s=1000.0)):
        sim = SimCore(world, cfg, seed=3)
        sim.add_robot("a", (1.0, 2.3, 0.0))
        sim.set_cmd("a", 0.4, 0.3)
        odom = [o for _ in range(200) for _, o in sim.step().odometry]
        runs.append((sim.truth()["a"], np.array([[o.x, o.y, o.theta] for o in odom])))
    assert runs[0][0] == runs[1][0]
    assert np.array_equal(runs[0][1], runs[1][1])


def test_batteries_in_a_world_without_a_dock_are_refused_naming_the_world(world: World) -> None:
    docked = dataclasses.replace(world, docks=())
    with pytest.raises(ConfigError, match=f"{world.source}: robot.battery is on, but the world"):
        SimCore(docked, _cfg())


def test_the_report_gives_each_robot_its_battery_block(world: World) -> None:
    dock = world.dock
    assert dock is not None
    sim = SimCore(world, _cfg(capacity_s=100.0))
    sim.add_robot("off", (1.0, 2.3, 0.0))
    sim.set_cmd("off", 0.3, 0.0)
    _run(sim, 1.0)
    sim.add_robot("on", (dock[0], dock[1], dock[2] + math.pi))
    _run(sim, 2.0)
    summary = sim.summary(0.0)
    on, off = summary.robots.index("on"), summary.robots.index("off")
    assert battery_of(summary, on) == {
        "battery": {"min_charge": 1.0, "charges": 1, "charging_s": 2.0, "parked": True}
    }
    block = battery_of(summary, off)["battery"]
    assert block["parked"] is False and block["charges"] == 0 and block["min_charge"] < 1.0
    assert battery_of(SimCore(world, load_fleet_config()).summary(0.0), 0) == {}


def test_a_robot_starts_with_the_configured_charge_and_keeps_its_own_when_it_comes_back(
    world: World,
) -> None:
    sim = SimCore(world, _cfg(capacity_s=100.0, start_charge=0.4))
    sim.add_robot("a", (1.0, 2.3, 0.0))
    assert _charge(sim, "a") == pytest.approx(0.4)
    _run(sim, 1.0)
    left = _charge(sim, "a")
    assert left < 0.4
    sim.remove_robot("a")
    sim.add_robot("a", (1.0, 2.3, 0.0))  # respawned: the battery it had, not a new one
    assert _charge(sim, "a") == pytest.approx(left)


@pytest.mark.parametrize("start", [0.0, 1.5])
def test_a_start_charge_outside_0_to_1_is_refused(start: float) -> None:
    with pytest.raises(ValueError, match="start_charge"):
        _cfg(start_charge=start).robot.battery.validate()
