"""CARMEN recording of a simulated robot (`fleet sim --record-carmen`): the recorder on SimCore,
and the real `fleet sim` process stopped by SIGTERM."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from fleet.carmen import LaserRecord, OdomRecord, read_log
from fleet.config import resolve_world
from fleet.params import load_fleet_config
from fleet.world import load_world
from sim_server.recorder import CarmenRecorder, read_truth, truth_path_for

SMALL = Path(__file__).resolve().parents[2] / "configs" / "worlds" / "small.yaml"


def _drive(rec: CarmenRecorder, seconds: float) -> dict[str, list]:
    """Two robots driving arcs in the home world; returns what the sim emitted per robot."""
    from sim_server.core import SimCore

    cfg = load_fleet_config()
    world = load_world(resolve_world("home"), cfg.robot.radius)
    starts = world.start_poses(2, cfg.robot.radius)
    core = SimCore(world, cfg, seed=3)
    core.add_robot("a", starts[0])
    core.add_robot("b", starts[1])
    core.set_cmd("a", 0.2, 0.3)
    core.set_cmd("b", 0.15, -0.4)
    seen: dict[str, list] = {"scans": [], "odom": [], "truth": []}
    for _ in range(round(seconds * cfg.sim.physics_hz)):
        out = core.step()
        rec.record(out.odometry, out.scans, core.truth)
        seen["odom"] += [(rid, m) for rid, m in out.odometry if rid == rec.robot]
        for rid, scan in out.scans:
            if rid == rec.robot:
                seen["scans"].append(scan)
                seen["truth"].append(core.truth()[rid])
    return seen


@pytest.mark.parametrize("robot", [None, "b"])
def test_recorded_log_has_every_scan_and_odometry_of_the_robot_and_matching_truth(
    tmp_path: Path, robot: str | None
) -> None:
    path = tmp_path / "run.log"
    with CarmenRecorder(path, robot) as rec:
        seen = _drive(rec, 4.0)
    assert rec.robot == (robot or "a")
    log = read_log(path)
    scans = [r for r in log.records if isinstance(r, LaserRecord)]
    odoms = [r for r in log.records if isinstance(r, OdomRecord)]
    assert len(seen["scans"]) == 40
    assert len(scans) == len(seen["scans"]) == rec.scans
    assert len(odoms) == len(seen["odom"]) == 200
    assert log.truncated_line is None
    assert [s.kind for s in scans] == ["ROBOTLASER1"] * len(scans)

    for rec_scan, sim_scan in zip(scans, seen["scans"], strict=True):
        assert rec_scan.timestamp == pytest.approx(sim_scan.stamp, abs=1e-6)
        assert rec_scan.angle_min == pytest.approx(sim_scan.angle_min, abs=1e-6)
        assert rec_scan.angle_increment == pytest.approx(sim_scan.angle_increment, abs=1e-9)
        sim = np.where(np.isfinite(sim_scan.ranges), sim_scan.ranges, sim_scan.range_max)
        assert np.abs(rec_scan.ranges - sim).max() <= 5e-4
    odom_t = np.array([o.stamp for _, o in seen["odom"]])
    for s in scans:
        _, o = seen["odom"][int(np.argmin(np.abs(odom_t - s.timestamp)))]
        assert o.stamp == pytest.approx(s.timestamp)
        assert s.laser_pose == pytest.approx((o.x, o.y, o.theta), abs=1e-5)

    truth = read_truth(truth_path_for(path))
    assert truth.shape == (len(scans), 4)
    assert truth[:, 0] == pytest.approx([s.timestamp for s in scans], abs=1e-6)
    assert truth[:, 1:] == pytest.approx(np.array(seen["truth"]), abs=1e-5)
    moved = np.hypot(*(truth[-1, 1:3] - truth[0, 1:3]))
    assert moved > 0.3


def test_truth_file_with_a_wrong_header_is_refused(tmp_path: Path) -> None:
    bad = tmp_path / "x.truth.csv"
    bad.write_text("time,x,y\n0,0,0\n")
    with pytest.raises(ValueError, match=r"x\.truth\.csv:1"):
        read_truth(bad)


@pytest.mark.integration
@pytest.mark.timeout(90)
def test_fleet_sim_records_until_sigterm(tmp_path: Path) -> None:
    """`fleet sim --record-carmen` over a real router: spawn a robot, drive it; the log is
    readable while the sim runs (flushed per scan), and after SIGTERM it parses to the end and
    every scan has its truth row."""
    from fleet.bus import Bus, open_router
    from fleet.protocol import LaserScan, SpawnReply, SpawnRequest, Twist
    from fleet.supervisor.launcher import free_port

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = open_router([endpoint])
    path = tmp_path / "sim.log"
    cmd = [sys.executable, "-m", "fleet.cli", "sim", "--world", str(SMALL), "--speed", "4"]
    cmd += ["--connect", endpoint, "--record-carmen", str(path)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        with Bus("test", "recorder-test", [endpoint]) as bus:
            deadline = time.monotonic() + 30
            start = load_world(SMALL).start_poses(1, 0.17)[0]
            reply = None
            while reply is None and time.monotonic() < deadline:
                try:
                    reply = bus.request(
                        bus.keys.sim_spawn(), SpawnRequest("r0", *start), SpawnReply, timeout=1.0
                    )
                except (TimeoutError, RuntimeError):
                    time.sleep(0.3)
            assert reply is not None and reply.ok, "the sim did not answer the spawn request"
            # answer every scan as an agent does (the command stamped with the scan it
            # answers), so the lockstep lets the sim run on
            cmd_vel = bus.keys.robot("r0", "cmd_vel")
            answered: list[float] = []

            def answer(_key: str, scan: LaserScan) -> None:
                bus.publish(cmd_vel, Twist(scan.stamp, 0.2, 0.4), control=True)
                answered.append(scan.stamp)

            bus.subscribe(bus.keys.robot("r0", "scan"), LaserScan, answer)
            while len(answered) < 20 and time.monotonic() < deadline + 30:
                time.sleep(0.1)
        running = read_log(path)
        running_truth = read_truth(truth_path_for(path))
        assert len(running.scans) >= 10, "scans are not flushed while the sim runs"
        assert len(running_truth) >= len(running.scans), "truth is not flushed with the scans"
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(20) == 0, proc.stderr.read().decode(errors="replace")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        router.close()
    log = read_log(path)
    assert log.truncated_line is None
    assert len(log.scans) >= 20
    truth = read_truth(truth_path_for(path))
    assert truth[:, 0] == pytest.approx([s.timestamp for s in log.scans], abs=1e-6)
    assert np.hypot(*(truth[-1, 1:3] - truth[0, 1:3])) > 0.05
