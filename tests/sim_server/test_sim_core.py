"""SimCore in the small world: debounced collisions, ground-truth cleaning, sensor rates, lidar."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from fleet.config import configs_dir
from fleet.params import FleetConfig, load_fleet_config
from fleet.protocol import Collision
from fleet.world import World, load_world
from planners.polyline import count_turns, path_length, simplify
from sim_server.core import TRAJECTORY_SAMPLE_M, TURN_SIMPLIFY_TOL_M, SimCore


@pytest.fixture(scope="module")
def world() -> World:
    return load_world(configs_dir() / "worlds" / "small.yaml")


@pytest.fixture(scope="module")
def cfg() -> FleetConfig:
    return load_fleet_config()


def _run(sim: SimCore, seconds: float) -> list[Collision]:
    events: list[Collision] = []
    for _ in range(round(seconds / sim.dt)):
        events += sim.step().collisions
    return events


def _counters(sim: SimCore) -> dict[str, tuple[int, int]]:
    s = sim.summary(0.0)
    return {
        r: (int(w), int(c))
        for r, w, c in zip(s.robots, s.wall_collisions, s.robot_collisions, strict=True)
    }


def test_driving_into_a_wall_is_one_collision(world: World, cfg: FleetConfig) -> None:
    sim = SimCore(world, cfg)
    # Heading -x along y = 2.3: the inner face of the west wall is at x = 0.05.
    sim.add_robot("r0", (1.0, 2.3, math.pi))
    sim.set_cmd("r0", 0.5, 0.0)
    events = _run(sim, 5.0)  # reaches the wall after ~2 s, then keeps pushing for ~3 s
    assert len(events) == 1, events
    ev = events[0]
    assert (ev.kind, ev.robot, ev.other) == ("wall", "r0", "")
    assert ev.x == pytest.approx(0.05, abs=0.05)
    assert ev.y == pytest.approx(2.3, abs=0.1)
    assert _counters(sim) == {"r0": (1, 0)}


def test_robots_driving_into_each_other_are_one_collision(world: World, cfg: FleetConfig) -> None:
    sim = SimCore(world, cfg)
    sim.add_robot("a", (1.0, 2.3, 0.0))
    sim.add_robot("b", (2.6, 2.3, math.pi))
    sim.set_cmd("a", 0.3, 0.0)
    sim.set_cmd("b", 0.3, 0.0)
    events = _run(sim, 4.0)
    assert len(events) == 1, events
    ev = events[0]
    assert ev.kind == "robot"
    assert {ev.robot, ev.other} == {"a", "b"}
    assert ev.x == pytest.approx(1.8, abs=0.15)
    assert _counters(sim) == {"a": (0, 1), "b": (0, 1)}


def test_bouncing_off_a_wall_within_a_second_is_one_collision(
    world: World, cfg: FleetConfig
) -> None:
    brisk = dataclasses.replace(cfg, robot=dataclasses.replace(cfg.robot, acc_lim_x=50.0))
    sim = SimCore(world, brisk)
    touching = 0.05 + cfg.robot.radius
    sim.add_robot("r0", (0.4, 2.3, math.pi))

    def drive(v: float, seconds: float) -> list[Collision]:
        sim.set_cmd("r0", v, 0.0)
        return _run(sim, seconds)

    first = drive(0.3, 0.7)
    assert [e.kind for e in first] == ["wall"]
    assert not drive(-0.3, 0.2)
    assert sim.truth()["r0"][0] > touching + 0.01, "the robot did not leave the wall"
    assert not drive(0.3, 0.3), "a re-touch within the debounce time counted again"
    assert sim.truth()["r0"][0] < touching
    drive(-0.3, 1.0)
    drive(0.0, 1.0)
    second = drive(0.3, 1.5)
    assert [e.kind for e in second] == ["wall"]
    assert second[0].stamp - first[0].stamp > 1.0
    assert _counters(sim) == {"r0": (2, 0)}


def test_a_robot_pushing_a_wall_stays_outside_it(world: World, cfg: FleetConfig) -> None:
    sim = SimCore(world, cfg)
    sim.add_robot("r0", (1.0, 2.3, math.pi))
    sim.set_cmd("r0", 0.5, 0.0)
    _run(sim, 5.0)
    assert sim.truth()["r0"][0] >= 0.05 + cfg.robot.radius - 0.02


def test_robots_pushing_each_other_do_not_overlap(world: World, cfg: FleetConfig) -> None:
    sim = SimCore(world, cfg)
    sim.add_robot("a", (1.0, 2.3, 0.0))
    sim.add_robot("b", (2.6, 2.3, math.pi))
    sim.set_cmd("a", 0.3, 0.0)
    sim.set_cmd("b", 0.3, 0.0)
    _run(sim, 4.0)
    t = sim.truth()
    assert math.dist(t["a"][:2], t["b"][:2]) >= 2 * cfg.robot.radius - 0.02


def test_standing_still_does_not_add_coverage(world: World, cfg: FleetConfig) -> None:
    sim = SimCore(world, cfg)
    sim.add_robot("r0", (1.0, 2.3, 0.0))
    sim.step()
    coverage, visits = sim.cleaning.coverage(), sim.cleaning.visits.copy()
    assert coverage > 0
    _run(sim, 2.0)
    assert sim.cleaning.coverage() == coverage
    assert np.array_equal(sim.cleaning.visits, visits)
    assert sim.cleaning.repetition() == 0.0


def test_straight_line_sweeps_a_band_of_cleaning_width(world: World, cfg: FleetConfig) -> None:
    sim = SimCore(world, cfg)
    x0 = 0.8
    sim.add_robot("r0", (x0, 2.3, 0.0))
    sim.set_cmd("r0", 0.5, 0.0)
    while sim.truth()["r0"][0] < x0 + 0.85:
        sim.step()
    sim.set_cmd("r0", 0.0, 0.0)
    _run(sim, 1.5)
    x, y, _ = sim.truth()["r0"]
    driven = x - x0
    assert driven == pytest.approx(1.0, abs=0.15)
    assert y == pytest.approx(2.3, abs=1e-6)
    width = cfg.robot.cleaning_width
    expected = width * driven + math.pi * (width / 2) ** 2
    swept = np.count_nonzero(sim.cleaning.visits) * cfg.sim.cell_size**2
    assert swept == pytest.approx(expected, rel=0.1)
    assert sim.cleaning.visits.max() == 1
    assert sim.cleaning.repetition() == pytest.approx(0.0, abs=0.01)
    # The band lies where the robot drove: between the start and end discs, |dy| ≤ width/2.
    g = sim.cleaning.grid
    rc = np.argwhere(sim.cleaning.visits > 0)
    pts = g.cell_to_world(rc)
    assert np.all(np.abs(pts[:, 1] - 2.3) <= width / 2 + g.resolution)
    assert pts[:, 0].min() >= x0 - width / 2 - g.resolution
    assert pts[:, 0].max() <= x + width / 2 + g.resolution


def test_scans_at_10_hz_and_odometry_at_50_hz(world: World, cfg: FleetConfig) -> None:
    sim = SimCore(world, cfg)
    sim.add_robot("r0", (1.0, 2.3, 0.0))
    sim.add_robot("r1", (1.0, 0.9, 0.0))
    scans, odometry = [], []
    for _ in range(round(2.0 / sim.dt)):
        out = sim.step()
        scans += [m.stamp for r, m in out.scans if r == "r0"]
        odometry += [m.stamp for r, m in out.odometry if r == "r0"]
    assert sim.t == pytest.approx(2.0)
    assert len(scans) == 20
    assert len(odometry) == 100
    assert np.diff(scans) == pytest.approx(np.full(19, 0.1))
    assert np.diff(odometry) == pytest.approx(np.full(99, 0.02))


def test_add_robot_inside_the_table_is_refused(world: World, cfg: FleetConfig) -> None:
    sim = SimCore(world, cfg)
    with pytest.raises(ValueError):
        sim.add_robot("r0", (2.4, 1.6, 0.0))
    with pytest.raises(ValueError):  # free centre, but the disc overlaps the table edge
        sim.add_robot("r0", (2.4, 1.3 - cfg.robot.radius / 2, 0.0))
    assert sim.robots == {}
    sim.add_robot("r0", (1.0, 2.3, 0.0))
    with pytest.raises(ValueError):
        sim.add_robot("r1", (1.2, 2.3, 0.0))


def test_noise_free_lidar_matches_the_walls(world: World, cfg: FleetConfig) -> None:
    quiet = dataclasses.replace(cfg, lidar=dataclasses.replace(cfg.lidar, noise_sigma=0.0))
    sim = SimCore(world, quiet)
    x, y = 2.4, 2.3  # above the table, whose top edge is at y = 1.9
    sim.add_robot("r0", (x, y, 0.0))
    ((rid, scan),) = sim.scan_all()
    assert rid == "r0"
    angles = scan.angle_min + scan.angle_increment * np.arange(len(scan.ranges))

    def beam(angle: float) -> float:
        i = int(np.argmin(np.abs(np.angle(np.exp(1j * (angles - angle))))))
        assert angles[i] == pytest.approx(angle, abs=1e-9) or abs(abs(angles[i]) - math.pi) < 1e-9
        return float(scan.ranges[i])

    inner = 0.05  # half the wall thickness
    assert beam(0.0) == pytest.approx(4.0 - inner - x, abs=1e-3)  # east wall
    assert beam(math.pi / 2) == pytest.approx(3.0 - inner - y, abs=1e-3)  # north wall
    assert beam(-math.pi) == pytest.approx(x - inner, abs=1e-3)  # west wall
    assert beam(-math.pi / 2) == pytest.approx(y - 1.9, abs=1e-3)  # top edge of the table
    # Turned by 90°, "straight ahead" is the north wall.
    sim2 = SimCore(world, quiet)
    sim2.add_robot("r0", (x, y, math.pi / 2))
    ((_, scan2),) = sim2.scan_all()
    ahead = int(np.argmin(np.abs(angles)))
    assert scan2.ranges[ahead] == pytest.approx(3.0 - inner - y, abs=1e-3)


def test_straight_drive_cleans_exactly_the_capsule_between_start_and_end(
    world: World, cfg: FleetConfig
) -> None:
    sim = SimCore(world, cfg)
    start = np.array([0.8, 2.3])
    sim.add_robot("r0", (*start, 0.0))
    sim.set_cmd("r0", 0.5, 0.0)
    _run(sim, 2.37)  # not a whole number of cleaning updates: summary() sweeps the rest
    end = np.array(sim.truth()["r0"][:2])
    sim.summary(0.0)
    g = sim.cleaning.grid
    centres = g.cell_to_world(np.argwhere(np.ones(g.shape, dtype=bool)))
    seg = end - start
    along = np.clip((centres - start) @ seg / (seg @ seg), 0.0, 1.0)
    dist = np.hypot(*(centres - start - along[:, None] * seg).T)
    capsule = (dist < cfg.robot.cleaning_width / 2 - 1e-9).reshape(g.shape)
    np.testing.assert_array_equal(sim.cleaning.visits > 0, capsule)
    assert sim.cleaning.visits.max() == 1


def test_a_robot_that_leaves_keeps_its_metrics_and_its_last_sweep(
    world: World, cfg: FleetConfig
) -> None:
    sim = SimCore(world, cfg)
    sim.add_robot("r0", (0.8, 2.3, 0.0))
    sim.set_cmd("r0", 0.5, 0.0)
    _run(sim, 1.55)
    x_left = sim.truth()["r0"][0]
    sim.remove_robot("r0")
    assert sim.truth() == {}
    assert not sim.step().odometry
    summary = sim.summary(0.0)
    assert summary.robots == ["r0"]
    assert summary.path_length_m[0] == pytest.approx(x_left - 0.8, abs=1e-9)
    g = sim.cleaning.grid
    swept_x = g.cell_to_world(np.argwhere(sim.cleaning.visits > 0))[:, 0]
    radius = cfg.robot.cleaning_width / 2
    # The brush was swept right up to where the robot left, not to its last 10 Hz update.
    assert swept_x.max() > x_left + radius - g.resolution
    # Back elsewhere: a fresh pass, and the distance driven continues from where it stopped.
    sim.add_robot("r0", (3.0, 0.6, math.pi / 2))
    sim.set_cmd("r0", 0.3, 0.0)
    _run(sim, 1.0)
    y = sim.truth()["r0"][1]
    assert sim.summary(0.0).path_length_m[0] == pytest.approx(x_left - 0.8 + y - 0.6, abs=1e-6)
    assert sim.cleaning.visits.max() == 1


def test_tick_is_a_step_with_truth_and_summary_when_due(world: World, cfg: FleetConfig) -> None:
    sim = SimCore(world, cfg)
    sim.add_robot("r0", (1.0, 1.0, 0.0))
    summaries = []
    for k in range(round(3.0 / sim.dt)):
        sim.set_cmd("r0", 0.3, 0.6 * math.sin(0.5 * k * sim.dt) + 0.5)
        out = sim.tick(0.0)
        assert bool(out.truth) == (sim.steps % sim.truth_every == 0)
        if out.truth:
            assert out.truth == sim.truth()
        if out.summary is not None:
            summaries.append(out.summary)
    assert len(summaries) == round(3.0 * cfg.sim.coverage_hz)
    last = summaries[-1]
    points = sim.robots["r0"].trajectory.points()
    assert last.turns[0] == count_turns(simplify(points, TURN_SIMPLIFY_TOL_M))
    assert last.path_length_m[0] == pytest.approx(path_length(points), abs=TRAJECTORY_SAMPLE_M)


def test_a_robot_placed_in_its_own_frame_counts_odometry_from_zero(
    world: World, cfg: FleetConfig
) -> None:
    """Its odometry starts at (0, 0, 0) where it stands and follows the body from there, so an
    agent that is not told its start learns nothing of it from odometry; the other robot's
    odometry still starts at its true pose."""
    sim = SimCore(world, cfg)
    sim.add_robot("known", (1.0, 1.0, 0.0))
    sim.add_robot("lost", (1.0, 2.3, math.pi / 2), own_frame=True)
    sim.set_cmd("lost", 0.2, 0.0)
    odom: dict[str, tuple[float, ...]] = {}
    for _ in range(round(2.0 / sim.dt)):
        for rid, msg in sim.step().odometry:
            odom[rid] = (msg.x, msg.y, msg.theta)
    x, y, theta = odom["lost"]
    true_x, true_y, _ = sim.truth()["lost"]
    # facing +y in the world is facing +x in its own frame
    assert x == pytest.approx(true_y - 2.3, abs=0.03)
    assert y == pytest.approx(1.0 - true_x, abs=0.03)
    assert theta == pytest.approx(0.0, abs=0.03)
    assert x > 0.2
    assert odom["known"][:2] == pytest.approx((1.0, 1.0), abs=0.01)
