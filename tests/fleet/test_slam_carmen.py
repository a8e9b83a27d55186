"""CARMEN log parsing and writing, and `fleet slam replay` on a log written from a simulation."""

from __future__ import annotations

import gzip
import json
import math
from pathlib import Path

import numpy as np
import pytest
from slam_sim import loop_route, room_segments, scan
from typer.testing import CliRunner

from fleet.carmen import (
    CarmenParseError,
    LaserRecord,
    OdomRecord,
    format_flaser,
    format_odom,
    format_param,
    format_robotlaser1,
    param_value,
    parse_lines,
    read_log,
)

SLAM_DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "slam"
ACES = SLAM_DATA / "aces-corrected.log.gz"
FR079 = SLAM_DATA / "freiburg-079-corrected.log.gz"

# Lines copied verbatim from the head of freiburg-079-corrected.log (the FLASER shortened to 4
# beams, its geometry then given by the same PARAM lines) and of aces-corrected.log.
FR079_LINES = [
    "# message formats defined: PARAM SYNC ODOM FLASER RLASER",
    "# PARAM param_name param_value",
    "PARAM robot_allow_rear_motion off 1071078718.462310 merci 1071078718.462309",
    "PARAM robot_front_laser_max 80.99 1071078718.462518 merci 1071078718.462517",
    "PARAM laser_front_laser_dev /dev/usb/ttyUSB1 1071078718.467646 merci 1071078718.467644",
    "PARAM laser_front_laser_resolution 0.5 1071078718.467699 merci 1071078718.467699",
    "NEFF 10",
    "ODOM 0 0 0 0 0 0 0.015885 pippo 0.015885",
    "FLASER 4 1.65 1.66 1.63 81.91 0.00123601 -0.00106807 2.85e-05 0.00123601 -0.00106807 "
    "2.85e-05 0.227623 pippo 0.227623",
]
ACES_LINES = [
    "PARAM robot_use_laser on nohost 0",
    "PARAM simulator_num_readings 180 nohost 0",
    "ODOM 0 0 0 0 0 0 0.110201 pippo 0.110201",
    "FLASER 4 6.66 6.86 7.16 50 0.89706 -0.180771 -0.454003 0.89706 -0.180771 -0.454003 "
    "21.0199 pippo 21.0199",
]

FLASER_4 = "FLASER 4 1.0 2.0 3.0 4.0 0.1 0.2 0.3 0.4 0.5 0.6 100.5 host 100.6"
ODOM = "ODOM 1.0 2.0 0.5 0.3 0.1 0.0 101.0 host 101.1"
ROBOTLASER = (
    "ROBOTLASER1 0 -1.5 3.0 1.0 20.0 0.01 0 4 1.0 2.0 3.0 4.0 2 0.5 0.5 "
    "1.0 1.1 0.2 0.9 1.0 0.2 0.3 0.0 0.5 0.3 0.0 102.0 host 102.1"
)


def test_comments_params_and_messages():
    log = parse_lines(
        [
            "# a comment",
            "",
            "PARAM robot_front_laser_max 50.0",
            FLASER_4,
            "SYNC x y",
            ODOM,
            ROBOTLASER,
        ]
    )
    assert log.params == {"robot_front_laser_max": "50.0"}  # a PARAM without the suffix
    assert log.skipped == {"SYNC": 1}
    assert log.truncated_line is None
    flaser, odom, robot = log.records
    assert isinstance(flaser, LaserRecord) and isinstance(odom, OdomRecord)
    np.testing.assert_array_equal(flaser.ranges, [1, 2, 3, 4])
    assert flaser.laser_pose == (0.1, 0.2, 0.3) and flaser.robot_pose == (0.4, 0.5, 0.6)
    assert flaser.timestamp == 100.5 and flaser.max_range == 50.0 and flaser.line == 4
    assert flaser.angle_min == pytest.approx(-math.pi / 2)
    assert flaser.angle_increment == pytest.approx(math.pi / 4)  # 180° over 4 beams
    assert odom.pose == (1.0, 2.0, 0.5) and odom.tv == 0.3 and odom.line == 6
    assert robot.kind == "ROBOTLASER1" and robot.angle_min == -1.5 and robot.angle_increment == 1.0
    assert robot.laser_pose == (1.0, 1.1, 0.2) and robot.robot_pose == (0.9, 1.0, 0.2)
    assert robot.max_range == 20.0 and robot.timestamp == 102.0


def test_flaser_angles_default_and_from_params():
    ranges = " ".join(["1.0"] * 181)
    line = f"FLASER 181 {ranges} 0 0 0 0 0 0 1.0 h 1.0"
    assert parse_lines([line]).scans[0].angle_increment == pytest.approx(math.radians(1.0))
    ranges = " ".join(["1.0"] * 180)
    line = f"FLASER 180 {ranges} 0 0 0 0 0 0 1.0 h 1.0"
    assert parse_lines([line]).scans[0].angle_increment == pytest.approx(math.radians(1.0))
    log = parse_lines(
        ["PARAM laser_front_laser_fov 100", "PARAM laser_front_laser_resolution 0.5", line]
    )
    assert log.scans[0].angle_min == pytest.approx(math.radians(-50))
    assert log.scans[0].angle_increment == pytest.approx(math.radians(0.5))


@pytest.mark.parametrize(
    ("tokens", "value"),
    [
        ("PARAM a 0.5 1071078718.467699 merci 1071078718.467699", "0.5"),
        ("PARAM a /dev/usb/ttyUSB1 1071078718.467646 merci 1071078718.467644", "/dev/usb/ttyUSB1"),
        ("PARAM a on nohost 0", "on"),
        ("PARAM a 180 nohost 0", "180"),
        ("PARAM a 50.0", "50.0"),
        ("PARAM a two words 1.0 host 1.0", "two words"),
    ],
)
def test_param_value_drops_the_timestamps_and_host(tokens, value):
    assert param_value(tokens.split()) == value


def test_real_freiburg_lines_parse():
    log = parse_lines(FR079_LINES, source="fr079")
    assert log.params["laser_front_laser_resolution"] == "0.5"
    assert log.params["laser_front_laser_dev"] == "/dev/usb/ttyUSB1"
    assert log.params["robot_allow_rear_motion"] == "off"
    assert log.skipped == {"NEFF": 1}
    odom, flaser = log.records
    assert isinstance(odom, OdomRecord) and odom.hostname == "pippo"
    assert odom.timestamp == 0.015885 and odom.logger_timestamp == 0.015885
    assert flaser.kind == "FLASER" and flaser.max_range == 80.99
    assert flaser.angle_increment == pytest.approx(math.radians(0.5))
    assert flaser.angle_min == pytest.approx(math.radians(-1.0))  # 4 beams at 0.5°: a 2° fov
    assert flaser.laser_pose == (0.00123601, -0.00106807, 2.85e-05)
    assert flaser.timestamp == 0.227623 and flaser.hostname == "pippo"


def test_real_aces_lines_parse():
    log = parse_lines(ACES_LINES, source="aces")
    assert log.params == {"robot_use_laser": "on", "simulator_num_readings": "180"}
    (odom, flaser) = log.records
    assert odom.pose == (0.0, 0.0, 0.0) and odom.timestamp == 0.110201
    np.testing.assert_array_equal(flaser.ranges, [6.66, 6.86, 7.16, 50])
    assert flaser.angle_min == pytest.approx(-math.pi / 2)
    assert flaser.angle_increment == pytest.approx(math.pi / 4)
    assert flaser.max_range == 81.9 and flaser.logger_timestamp == 21.0199


def test_rear_laser_has_its_own_geometry_and_is_not_replayed_with_the_front():
    lines = [
        "PARAM laser_rear_laser_fov 90 1.0 h 1.0",
        "PARAM robot_rear_laser_max 20 1.0 h 1.0",
        "RLASER 3 1.0 2.0 3.0 0 0 3.1416 0 0 0 5.0 h 5.0",
        FLASER_4,
    ]
    log = parse_lines(lines)
    rear, front = log.scans
    assert rear.kind == "RLASER" and rear.max_range == 20.0
    assert rear.angle_min == pytest.approx(math.radians(-45))
    assert rear.angle_increment == pytest.approx(math.radians(45))
    assert log.front_scans == [front]
    assert [r.kind for r in parse_lines(lines[:3]).front_scans] == ["RLASER"]


def test_a_bad_laser_param_names_its_own_line():
    lines = [FLASER_4, "PARAM laser_front_laser_resolution half 1.0 h 1.0", FLASER_4]
    with pytest.raises(CarmenParseError) as err:
        parse_lines(lines, source="run.log")
    assert str(err.value).startswith("run.log:2:") and "'half'" in str(err.value)


@pytest.mark.parametrize(
    ("path", "scans", "beams", "resolution_deg", "max_range"),
    [(ACES, 440, 180, 1.0, 81.9), (FR079, 4791, 360, 0.5, 80.99)],
)
def test_real_logs_read_whole(path, scans, beams, resolution_deg, max_range):
    if not path.exists():
        pytest.skip(f"{path} is absent (shared data not checked out)")
    log = read_log(path)
    assert len(log.scans) == scans and log.truncated_line is None
    assert {r.ranges.size for r in log.scans} == {beams}
    first = log.scans[0]
    assert first.angle_min == pytest.approx(-math.pi / 2)
    assert first.angle_increment == pytest.approx(math.radians(resolution_deg))
    assert first.max_range == max_range
    assert sum(isinstance(r, OdomRecord) for r in log.records) > scans
    stamps = [r.timestamp for r in log.scans]
    assert stamps == sorted(stamps)


def test_truncated_last_line_is_dropped_and_reported():
    log = parse_lines([FLASER_4, ODOM, "FLASER 4 1.0 2.0 3.0"])
    assert len(log.records) == 2 and log.truncated_line == 3


@pytest.mark.parametrize(
    ("line", "field"),
    [
        ("FLASER 4 1.0 2.0 x 4.0 0.1 0.2 0.3 0.4 0.5 0.6 100.5 host 100.6", "range_readings"),
        ("FLASER 4 1.0 2.0 3.0 4.0 0.1 0.2 0.3 0.4 0.5 0.6 100.5 host 100.6 7", "unexpected"),
        ("ODOM 1.0 2.0 zero 0.3 0.1 0.0 101.0 host 101.1", "odom_theta"),
        ("FLASER -3 1.0", "num_readings"),
        ("ROBOTLASER1 0 -1.5 3.0 1.0 20.0 0.01 0 4 1.0 2.0", "range_readings"),
    ],
)
def test_broken_line_in_the_middle_names_file_and_line(line, field):
    with pytest.raises(CarmenParseError) as err:
        parse_lines(["# header", FLASER_4, line, ODOM], source="run.log")
    assert str(err.value).startswith("run.log:3:")
    assert field in str(err.value)
    assert err.value.line == 3


def test_gzip_is_read_transparently(tmp_path):
    text = "\n".join(["PARAM a 1", FLASER_4, ODOM]) + "\n"
    gz = tmp_path / "log.gz"
    gz.write_bytes(gzip.compress(text.encode()))
    disguised = tmp_path / "log.clf"
    disguised.write_bytes(gzip.compress(text.encode()))
    plain = tmp_path / "log.txt"
    plain.write_text(text)
    for path in (gz, disguised, plain):
        log = read_log(path)
        assert [type(r) for r in log.records] == [LaserRecord, OdomRecord]


def test_writer_round_trips():
    ranges = np.array([1.25, 2.5, 6.0])
    flaser = format_flaser(ranges, (1.0, 2.0, 0.5), (1.1, 2.1, 0.6), 12.5, "sim", 12.5)
    robot = format_robotlaser1(
        ranges, -math.pi, 2 * math.pi / 3, 6.0, (1.0, 2.0, 0.5), (1.0, 2.0, 0.5), 12.6, "sim", 12.6
    )
    odom = format_odom((1.0, 2.0, 0.5), 0.3, 0.1, 0.0, 12.7, "sim", 12.7)
    log = parse_lines([format_param("robot_front_laser_max", 6.0), flaser, robot, odom])
    a, b, c = log.records
    np.testing.assert_allclose(a.ranges, ranges)
    assert (
        a.laser_pose == (1.0, 2.0, 0.5) and a.robot_pose == (1.1, 2.1, 0.6) and a.max_range == 6.0
    )
    assert b.angle_min == pytest.approx(-math.pi) and b.angle_increment == pytest.approx(
        2 * math.pi / 3
    )
    assert c.pose == (1.0, 2.0, 0.5) and c.timestamp == 12.7


def _write_sim_log(path, truth: np.ndarray) -> None:
    rng = np.random.default_rng(4)
    lines = ["# simulated room", format_param("robot_front_laser_max", 6.0)]
    for k, pose in enumerate(truth):
        ranges, a0, inc = scan(room_segments() + 0.02, pose, rng=rng)
        ranges = np.where(np.isfinite(ranges), ranges, 6.0)
        t = 0.1 * k
        p = tuple(pose)
        lines.append(format_robotlaser1(ranges, a0, inc, 6.0, p, p, t, "sim", t))
        lines.append(format_odom(p, 0.3, 0.0, 0.0, t, "sim", t))
    with gzip.open(path, "wt") as f:
        f.write("\n".join(lines) + "\n")


def test_fleet_slam_replay_writes_map_trajectory_and_timing(tmp_path):
    from fleet.cli import app

    truth = loop_route([(0.62, 0.52), (3.02, 0.52), (3.02, 2.22), (0.62, 2.22)], 0.3, 10.0)
    log = tmp_path / "room.log.gz"
    _write_sim_log(log, truth)
    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["slam", "replay", str(log), "--out", str(out), "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["scans"] == len(truth)
    assert summary["ms_per_scan_median"] > 0 and summary["replay_speedup"] > 0
    rows = (out / "trajectory.csv").read_text().splitlines()
    assert rows[0] == "t,x,y,theta" and len(rows) == len(truth) + 1
    traj = np.loadtxt(out / "trajectory.csv", delimiter=",", skiprows=1)
    assert np.hypot(*(traj[:, 1:3] - truth[:, :2]).T).max() < 0.05
    assert (out / "map.png").stat().st_size > 0 and (out / "map.yaml").exists()
    assert json.loads((out / "timing.json").read_text())["scans"] == len(truth)


def test_fleet_slam_replay_reports_the_broken_line(tmp_path):
    from fleet.cli import app

    log = tmp_path / "bad.log"
    log.write_text("\n".join([FLASER_4, "ODOM 1 2", ODOM]) + "\n")
    result = CliRunner().invoke(app, ["slam", "replay", str(log), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2
    assert f"{log}:2:" in result.output


def test_fleet_slam_replay_scores_against_the_truth_beside_the_log(tmp_path):
    from fleet.cli import app

    truth = loop_route([(0.62, 0.52), (3.02, 0.52), (3.02, 2.22), (0.62, 2.22)], 0.3, 10.0)
    log = tmp_path / "room.log.gz"
    _write_sim_log(log, truth)
    out = tmp_path / "out"
    plain = CliRunner().invoke(app, ["slam", "replay", str(log), "--out", str(out), "--json"])
    assert "ate_m" not in json.loads(plain.stdout)
    # The truth file is shifted 0.1 m along x from the poses the log's odometry holds, after
    # the first scan: ATE (aligned) stays small but the first relative poses are 0.1 m off.
    moved = truth.copy()
    moved[1:, 0] += 0.1
    rows = np.column_stack([0.1 * np.arange(len(truth)), moved])
    np.savetxt(
        tmp_path / "room.log.gz.truth.csv", rows, delimiter=",", header="t,x,y,theta", comments=""
    )
    result = CliRunner().invoke(app, ["slam", "replay", str(log), "--out", str(out), "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    for prefix in ("", "final_", "odom_"):
        for key in ("rpe1_m", "rpe5_m", "rpe20_m", "ate_m"):
            assert f"{prefix}{key}" in summary
    assert summary["odom_rpe1_m"] == pytest.approx(0.1 / (len(truth) - 1), abs=1e-3)
    assert summary["rpe1_m"] > 0.09 / len(truth)
    assert summary["ate_m"] < 0.1 and summary["final_ate_m"] < 0.1
    assert json.loads((out / "timing.json").read_text())["truth"].endswith("truth.csv")
    assert (out / "live.csv").read_text().startswith("t,x,y,theta")
