"""CARMEN log parsing and writing, and `fleet slam replay` on a log written from a simulation."""

from __future__ import annotations

import gzip
import json
import math

import numpy as np
import pytest
from slam_sim import loop_route, room_segments, scan
from typer.testing import CliRunner

from agents.slam.carmen import (
    CarmenParseError,
    LaserRecord,
    OdomRecord,
    format_flaser,
    format_odom,
    format_param,
    format_robotlaser1,
    parse_lines,
    read_log,
)

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
    assert log.params == {"robot_front_laser_max": "50.0"}
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
