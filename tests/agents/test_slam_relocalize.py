"""A restarted agent's SLAM state on disk, and its relocalization in the saved map.

The scenarios run a robot in SimCore on the built-in home world. Truth places the body and
checks the result; the code under test only sees the saved state, scans and odometry. SLAM
starts at the spawn pose, so its map frame is the world frame.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest
from slam_sim import box, drive_sim, scan

from agents.agent import respawn_window
from agents.pose_source import RelocalizingSlamPose, SlamPose, overlay
from agents.slam.geometry import wrap_angle
from agents.slam.persistence import (
    POSE_FILE,
    STATE_FILE,
    SavedState,
    StateError,
    load_state,
    save_pose,
    save_state,
    state_path,
)
from agents.slam.relocalize import relocalize
from agents.slam.slam import Slam
from agents.slam.slam_map import SlamMap
from fleet.config import resolve_world
from fleet.params import FleetConfig, load_fleet_config
from fleet.protocol import LaserScan, Odometry
from fleet.slam_params import SlamParams
from fleet.world import load_world
from sim_server.core import SimCore

Pose = tuple[float, float, float]
# (seconds, v, w) commands of the first run: up from the spawn pose, a turn and a curve
MAPPING_RUN = [(5.0, 0.25, 0.0), (6.0, 0.0, 0.6), (4.0, 0.2, 0.3)]


def _core(cfg: FleetConfig, world_name: str, pose: Pose, seed: int) -> SimCore:
    core = SimCore(load_world(resolve_world(world_name), cfg.robot.radius), cfg, seed=seed)
    core.add_robot("r", pose)
    return core


def _one_scan(core: SimCore) -> LaserScan:
    ((_, msg),) = core.scan_all()
    return msg


def _error(a: Sequence[float], b: Sequence[float]) -> tuple[float, float]:
    return math.hypot(a[0] - b[0], a[1] - b[1]), abs(float(wrap_angle(a[2] - b[2])))


def _relocalize(saved: SavedState, params: SlamParams, msg: LaserScan):
    return relocalize(
        saved.occupancy,
        params,
        msg.ranges.astype(np.float64),
        msg.angle_min,
        msg.angle_increment,
        saved.pose,
        params.reloc_window_xy,
        params.reloc_window_theta,
        msg.range_min,
        msg.range_max,
    )


@pytest.fixture(scope="module")
def cfg() -> FleetConfig:
    return load_fleet_config()


@pytest.fixture(scope="module")
def home_run(cfg: FleetConfig, tmp_path_factory: pytest.TempPathFactory) -> tuple[SavedState, Pose]:
    """Map part of the home's living room with SLAM, save the state; the state as loaded back
    and the true pose at the save."""
    world_start = load_world(resolve_world("home"), cfg.robot.radius).starts[0]
    core = _core(cfg, "home", world_start, seed=5)
    slam = SlamPose(cfg.slam, world_start, cfg.lidar.range_min, cfg.lidar.range_max)
    drive_sim(core, slam, MAPPING_RUN)
    directory = tmp_path_factory.mktemp("robot") / "state"
    save_state(directory, slam.occupancy(), slam.pose(), core.t)
    return load_state(directory), core.truth()["r"]


def _moved(pose: Pose, distance: float, direction: float, turn: float) -> Pose:
    return (
        pose[0] + distance * math.cos(direction),
        pose[1] + distance * math.sin(direction),
        float(wrap_angle(pose[2] + turn)),
    )


def test_saved_state_round_trips_map_pose_and_stamp(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    log_odds = rng.normal(size=(64, 96)).astype(np.float32)
    occupancy = SlamMap(log_odds, 0.05, (-1.225, 2.475))
    save_state(tmp_path / "a" / "b", occupancy, (1.5, -2.25, 3.0), 12.5)
    save_state(tmp_path / "a" / "b", occupancy, (1.0, 2.0, -0.5), 17.25)  # replaces
    state = load_state(tmp_path / "a" / "b")
    assert state.pose == (1.0, 2.0, -0.5) and state.stamp == 17.25
    assert state.occupancy.log_odds.dtype == np.float32
    np.testing.assert_array_equal(state.occupancy.log_odds, log_odds)
    assert state.occupancy.resolution == 0.05
    assert state.occupancy.origin == (-1.225, 2.475)
    assert sorted(p.name for p in (tmp_path / "a" / "b").iterdir()) == [STATE_FILE]


def test_the_newer_of_the_saved_poses_is_loaded(tmp_path: Path) -> None:
    occupancy = SlamMap(np.ones((32, 32), np.float32), 0.05, (0.0, 0.0))
    save_state(tmp_path, occupancy, (1.0, 1.0, 0.0), 10.0)
    save_pose(tmp_path, (1.2, 1.1, 0.5), 10.6)
    state = load_state(tmp_path)
    assert state.pose == (1.2, 1.1, 0.5) and state.stamp == 10.6
    save_state(tmp_path, occupancy, (1.3, 1.2, 0.6), 12.0)  # the map's pose is newer now
    assert load_state(tmp_path).pose == (1.3, 1.2, 0.6)
    assert sorted(p.name for p in tmp_path.iterdir()) == [POSE_FILE, STATE_FILE]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("{", "unreadable pose"),
        ('{"pose": [1, 2], "stamp": 3}', "unreadable pose"),
        ('{"pose": [1, 2, NaN], "stamp": 30}', "finite"),
        ('{"pose": [1, 2, 7], "stamp": 30}', "heading"),
    ],
)
def test_damaged_pose_file_raises_naming_it(tmp_path: Path, text: str, message: str) -> None:
    save_state(tmp_path, SlamMap(np.ones((8, 8), np.float32), 0.05, (0.0, 0.0)), (0, 0, 0), 1)
    (tmp_path / POSE_FILE).write_text(text)
    with pytest.raises(StateError, match=message) as err:
        load_state(tmp_path)
    assert str(tmp_path / POSE_FILE) in str(err.value)


def _write_npz(path: Path, **arrays: np.ndarray) -> None:
    full = {
        "version": np.array(1),
        "log_odds": np.zeros((4, 4), dtype=np.float32),
        "resolution": np.array(0.05),
        "origin": np.zeros(2),
        "pose": np.zeros(3),
        "stamp": np.array(1.0),
    }
    full.update(arrays)
    with path.open("wb") as f:
        np.savez(f, **{k: v for k, v in full.items() if v is not None})


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        ("missing", "no saved SLAM state"),
        ("garbage", "unreadable"),
        ("truncated", "unreadable"),
        ("no_pose", "missing pose"),
        ("pose_shape", "pose must be"),
        ("nan_map", "non-finite"),
        ("resolution", "resolution must be > 0"),
    ],
)
def test_missing_corrupt_or_inconsistent_state_raises_naming_the_file(
    tmp_path: Path, damage: str, message: str
) -> None:
    path = state_path(tmp_path)
    if damage in ("garbage", "truncated"):
        save_state(tmp_path, SlamMap(np.ones((32, 32), np.float32), 0.05, (0.0, 0.0)), (0, 0, 0), 1)
        data = path.read_bytes()
        path.write_bytes(b"not a zip file" * 10 if damage == "garbage" else data[: len(data) // 2])
    elif damage == "no_pose":
        _write_npz(path, pose=None)
    elif damage == "pose_shape":
        _write_npz(path, pose=np.zeros(2))
    elif damage == "nan_map":
        _write_npz(path, log_odds=np.full((4, 4), np.nan, dtype=np.float32))
    elif damage == "resolution":
        _write_npz(path, resolution=np.array(0.0))
    with pytest.raises(StateError, match=message) as err:
        load_state(tmp_path)
    assert str(path) in str(err.value)


@pytest.mark.parametrize(
    ("distance", "direction", "turn"),
    [(0.6, 0.3, math.radians(40)), (0.6, 2.2, math.radians(-40)), (0.4, -1.2, math.radians(150))],
)
def test_moved_robot_relocalizes_from_one_scan(
    cfg: FleetConfig,
    home_run: tuple[SavedState, Pose],
    distance: float,
    direction: float,
    turn: float,
) -> None:
    saved, truth_at_save = home_run
    assert _error(saved.pose, truth_at_save)[0] < 0.03  # the saved pose is SLAM's, near truth
    placed = _moved(truth_at_save, distance, direction, turn)
    core = _core(cfg, "home", placed, seed=11)
    result = _relocalize(saved, cfg.slam, _one_scan(core))
    assert result.ok, result.reason
    assert result.score >= cfg.slam.reloc_min_score and result.reason == ""
    xy, theta = _error(result.pose, placed)
    assert xy < 0.05 and theta < math.radians(2.0)


def test_scan_from_an_unseen_room_is_refused(
    cfg: FleetConfig, home_run: tuple[SavedState, Pose]
) -> None:
    saved, _ = home_run
    core = _core(cfg, "home", (9.0, 4.6, 0.3), seed=12)  # the study, never mapped
    result = _relocalize(saved, cfg.slam, _one_scan(core))
    assert not result.ok and "reloc_min_score" in result.reason


def test_scan_from_another_world_is_refused(
    cfg: FleetConfig, home_run: tuple[SavedState, Pose]
) -> None:
    saved, truth_at_save = home_run
    for k, pose in enumerate([(1.0, 1.0, 0.3), (3.0, 0.8, 2.0), (*truth_at_save[:2], 1.0)]):
        core = _core(cfg, "small", pose, seed=13 + k)
        result = _relocalize(saved, cfg.slam, _one_scan(core))
        assert not result.ok and result.reason, (pose, result)


def _symmetric_room_map(params: SlamParams) -> SlamMap:
    """A bare 4 m × 3 m room (same after half a turn about its centre), mapped with SLAM from
    exact odometry along a short path near the centre."""
    segments = np.array(box(0.0, 0.0, 4.0, 3.0))
    rng = np.random.default_rng(2)
    poses = [(1.7 + 0.05 * k, 1.5, 0.02 * k) for k in range(12)]
    slam = Slam(params, poses[0], range_min=0.1, range_max=6.0)
    for k, pose in enumerate(poses):
        ranges, a0, inc = scan(segments, np.array(pose), rng=rng)
        slam.process(ranges, a0, inc, pose, 0.1 * k)
    return slam.occupancy()


def test_symmetric_room_is_ambiguous_within_the_window_and_not_outside(
    cfg: FleetConfig,
) -> None:
    params = cfg.slam
    occupancy = _symmetric_room_map(params)
    truth = np.array([2.3, 1.65, 0.4])  # its mirror (1.7, 1.35, 0.4 − π) is 0.67 m away
    ranges, a0, inc = scan(np.array(box(0.0, 0.0, 4.0, 3.0)), truth, rng=np.random.default_rng(4))
    prior = (2.0, 1.5, 0.0)
    wide = relocalize(occupancy, params, ranges, a0, inc, prior, 1.0, math.pi, 0.1, 6.0)
    assert not wide.ok and wide.reason.startswith("ambiguous"), wide
    narrow = relocalize(occupancy, params, ranges, a0, inc, prior, 1.0, 1.0, 0.1, 6.0)
    assert narrow.ok, narrow.reason
    xy, theta = _error(narrow.pose, truth)
    assert xy < 0.05 and theta < math.radians(2.0)


def test_relocalizing_pose_source_localizes_then_tracks_the_robot(
    cfg: FleetConfig, home_run: tuple[SavedState, Pose]
) -> None:
    saved, truth_at_save = home_run
    placed = _moved(truth_at_save, 0.6, 0.3, math.radians(40))
    core = _core(cfg, "home", placed, seed=21)
    source = RelocalizingSlamPose(cfg.slam, saved, cfg.lidar.range_min, cfg.lidar.range_max)
    assert not source.localized and not source.failed and source.reason
    assert source.pose() == saved.pose
    assert source.occupancy() is saved.occupancy
    drive_sim(core, source, [(0.1, 0.0, 0.0)])  # until the first scan (10 Hz)
    assert source.localized and not source.failed and source.reason == ""
    xy, theta = _error(source.pose(), core.truth()["r"])
    assert xy < 0.05 and theta < math.radians(2.0)

    start_xy = np.array(core.truth()["r"][:2])
    worst = 0.0
    turn_to_west = (math.pi - placed[2]) / 0.5
    legs = [(turn_to_west, 0.0, 0.5), (5.6, 0.25, 0.0), (math.pi, 0.0, -0.5), (4.4, 0.25, 0.0)]
    legs += [(math.pi, 0.0, -0.5), (4.0, 0.25, 0.0)]
    travelled = 0.0
    for leg in legs:
        for _ in range(round(leg[0] / 0.5)):
            drive_sim(core, source, [(0.5, leg[1], leg[2])])
            truth = core.truth()["r"]
            worst = max(worst, _error(source.pose(), truth)[0])
        travelled += leg[0] * leg[1]
    assert core.robots["r"].wall_collisions == 0
    assert travelled > 3.0 and math.dist(core.truth()["r"][:2], start_xy) > 1.0
    xy, theta = _error(source.pose(), core.truth()["r"])
    assert worst < 0.06 and xy < 0.05 and theta < math.radians(2.0)
    # the new SLAM is on the saved map's lattice, so its map is laid over the saved one
    merged = source.occupancy()
    assert np.count_nonzero(merged.log_odds) > np.count_nonzero(saved.occupancy.log_odds)
    shift = (np.asarray(saved.occupancy.origin) - np.asarray(merged.origin)) / 0.05
    assert np.abs(shift - np.rint(shift)).max() < 1e-3


def test_relocalizing_pose_source_fails_after_max_scans_with_the_last_reason(
    cfg: FleetConfig, home_run: tuple[SavedState, Pose]
) -> None:
    saved, _ = home_run
    params = dataclasses.replace(cfg.slam, reloc_max_scans=3)
    core = _core(cfg, "home", (9.0, 4.6, 0.3), seed=22)
    source = RelocalizingSlamPose(params, saved, cfg.lidar.range_min, cfg.lidar.range_max)
    drive_sim(core, source, [(0.25, 0.0, 0.0)])
    assert not source.failed and not source.localized  # two attempts so far
    drive_sim(core, source, [(0.1, 0.0, 0.0)])
    assert source.failed and not source.localized
    assert source.reason.startswith("attempt 3: ") and "reloc_min_score" in source.reason
    assert source.pose() == saved.pose
    drive_sim(core, source, [(0.5, 0.0, 0.0)])  # five more scans: one more attempt (every third)
    assert source.reason.startswith("attempt 4: ")


def test_failed_relocalization_retries_and_succeeds_once_the_view_matches(
    cfg: FleetConfig, home_run: tuple[SavedState, Pose]
) -> None:
    """A robot that cannot find itself keeps trying now and then: carried back into the mapped
    room (the body is put there), it finds itself on a later try."""
    saved, truth_at_save = home_run
    params = dataclasses.replace(cfg.slam, reloc_max_scans=3)
    core = _core(cfg, "home", (9.0, 4.6, 0.3), seed=23)
    source = RelocalizingSlamPose(params, saved, cfg.lidar.range_min, cfg.lidar.range_max)
    drive_sim(core, source, [(0.35, 0.0, 0.0)])
    assert source.failed and not source.localized
    core.remove_robot("r")
    core.add_robot("r", _moved(truth_at_save, 0.3, 1.0, math.radians(30)))
    drive_sim(core, source, [(0.35, 0.0, 0.0)])
    assert source.localized, source.reason
    xy, theta = _error(source.pose(), core.truth()["r"])
    assert xy < 0.05 and theta < math.radians(2.0)


def test_near_window_resolves_a_room_that_looks_the_same_turned_half_a_turn(
    cfg: FleetConfig,
) -> None:
    """In the bare symmetric room the wide search is ambiguous; the window the body can have
    moved in since its last saved pose holds only the true pose, and the source takes it."""
    params = dataclasses.replace(cfg.slam, reloc_max_scans=2)
    occupancy = _symmetric_room_map(params)
    truth = (2.3, 1.65, 0.4)
    saved = SavedState(occupancy, (2.2, 1.5, 0.1), 1.0)
    segments = np.array(box(0.0, 0.0, 4.0, 3.0))
    ranges, a0, inc = scan(segments, np.array(truth), rng=np.random.default_rng(5))
    msg = LaserScan(2.0, a0, inc, 0.1, 6.0, ranges.astype(np.float32))
    odom = Odometry(2.0, *truth, 0.0, 0.0)
    wide_only = RelocalizingSlamPose(params, saved, 0.1, 6.0)
    near_first = RelocalizingSlamPose(params, saved, 0.1, 6.0, near=(0.45, 0.9))
    for source in (wide_only, near_first):
        source.on_odometry(odom)
        source.on_scan(msg)
    assert not wide_only.localized and "wide: ambiguous" in wide_only.reason
    assert near_first.localized, near_first.reason
    xy, theta = _error(near_first.pose(), truth)
    assert xy < 0.05 and theta < math.radians(2.0)


def test_respawn_window_bounds_the_drift_since_the_last_saved_pose(cfg: FleetConfig) -> None:
    xy, theta = respawn_window(cfg)
    r, seconds = cfg.robot, cfg.agent.pose_save_s + cfg.sim.max_lag_s
    assert xy > r.max_vel_x * seconds + r.max_vel_x**2 / (2 * r.acc_lim_x)
    assert theta > r.max_vel_theta * seconds
    # a mirror pose (turned half a turn) is never inside it with the defaults
    assert theta < math.pi / 2 and xy < 0.6
    slower = dataclasses.replace(cfg, agent=dataclasses.replace(cfg.agent, pose_save_s=2.0))
    assert respawn_window(slower)[0] > xy + 0.5 * r.max_vel_x


def test_overlay_keeps_the_saved_map_under_the_new_one() -> None:
    base = SlamMap(np.full((32, 64), 1.0, np.float32), 0.05, (0.025, 0.025))
    top_values = np.zeros((64, 32), np.float32)
    top_values[40:, :] = -2.0
    top = SlamMap(top_values, 0.05, (1.625, -1.575))  # 32 cells right of, 32 below base's origin
    merged = overlay(base, top)
    assert merged.shape == (64, 64) and merged.origin == pytest.approx((0.025, -1.575))
    np.testing.assert_array_equal(merged.log_odds[32:, :32], 1.0)  # base only
    np.testing.assert_array_equal(merged.log_odds[40:, 32:], -2.0)  # observed anew
    np.testing.assert_array_equal(merged.log_odds[32:40, 32:], 1.0)  # top unobserved there
    np.testing.assert_array_equal(merged.log_odds[:32, :32], 0.0)  # neither
    shifted = SlamMap(top_values, 0.05, (1.6, -1.575))  # another lattice: cannot merge
    assert overlay(base, shifted) is shifted
