"""The secured router on a real Zenoh router on loopback: `fleet certs lab` in a scratch dir,
`fleet router` with the shipped configs/zenoh/router-secure.json5 (TLS, passwords, access
control; multicast scouting off) on a free port, and fleet buses as the processes use them."""

from __future__ import annotations

import json
import stat
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import zenoh
from typer.testing import CliRunner

from fleet.bus import Bus, make_config
from fleet.cli import app
from fleet.protocol import Award, LaserScan, TruthPose, Twist
from fleet.security import shipped_router_config, users
from fleet.supervisor.launcher import free_port, wait_for_port

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ROOT / "configs" / "zenoh" / "router-secure.json5"
REFUSED_WITHIN_MS = 2000
DELIVERY_S = 5.0

pytestmark = pytest.mark.integration


class Router:
    """`fleet router` on the shipped secure config, and buses that connect to it."""

    def __init__(self, lab_parent: Path, endpoint: str) -> None:
        self.lab = lab_parent / "lab"
        self.endpoint = endpoint

    def bus(self, user: str, role: str = "agent") -> Bus:
        return Bus(role, user, [self.endpoint], zenoh_config=self.lab / f"{user}.json5")

    def open_raw(self, endpoint: str, config: Path | None, **extra: str) -> zenoh.Session:
        """A client session that gives up after REFUSED_WITHIN_MS."""
        conf = make_config("client", connect=[endpoint], zenoh_config=config)
        conf.insert_json5("connect/timeout_ms", str(REFUSED_WITHIN_MS))
        for key, value in extra.items():
            conf.insert_json5(key.replace(".", "/"), json.dumps(value))
        return zenoh.open(conf)


@pytest.fixture(scope="module")
def router(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Router]:
    work = tmp_path_factory.mktemp("secure")
    # the shipped router config reads lab/..., relative to the router's working dir
    result = CliRunner().invoke(app, ["certs", str(work / "lab"), "--robots", "3"])
    assert result.exit_code == 0, result.output
    port = free_port()
    endpoint = f"tls/127.0.0.1:{port}"
    log = (work / "router.log").open("w")
    proc = subprocess.Popen(
        [
            *(sys.executable, "-m", "fleet.cli", "router"),
            *("--listen", endpoint, "--zenoh-config", str(SHIPPED)),
        ],
        cwd=work,
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    try:
        assert wait_for_port("127.0.0.1", port, 20.0), (work / "router.log").read_text()
        yield Router(work, endpoint)
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        log.close()


class Inbox:
    """What a subscription received, by key."""

    def __init__(self) -> None:
        self.keys: list[str] = []
        self.lock = threading.Lock()

    def __call__(self, key: str, _msg: object) -> None:
        with self.lock:
            self.keys.append(key)

    def wait_for(self, key: str, timeout: float = DELIVERY_S) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self.lock:
                if key in self.keys:
                    return True
            time.sleep(0.05)
        return False


def test_the_shipped_config_is_what_fleet_certs_writes_for_three_robots() -> None:
    assert SHIPPED.read_text() == shipped_router_config()


def test_fleet_certs_keeps_keys_and_passwords_private(router: Router) -> None:
    for name in ["ca.key", "router.key", "credentials.txt", *(f"{u}.json5" for u in users(3))]:
        mode = stat.S_IMODE((router.lab / name).stat().st_mode)
        assert mode == 0o600, f"{name} is {oct(mode)}"
    lines = (router.lab / "credentials.txt").read_text().splitlines()
    assert [line.split(":")[0] for line in lines] == users(3)
    assert len({line.split(":")[1] for line in lines}) == len(lines)


def test_a_client_without_credentials_is_refused(router: Router) -> None:
    ca = str(router.lab / "ca.pem")
    with pytest.raises(zenoh.ZError):
        router.open_raw(router.endpoint, None, **{"transport.link.tls.root_ca_certificate": ca})
    with pytest.raises(zenoh.ZError):  # a user the router knows, with a wrong password
        router.open_raw(
            router.endpoint,
            None,
            **{
                "transport.link.tls.root_ca_certificate": ca,
                "transport.auth.usrpwd.user": "robot-0",
                "transport.auth.usrpwd.password": "not-its-password",
            },
        )
    with pytest.raises(zenoh.ZError):  # plain TCP to the TLS port
        router.open_raw(router.endpoint.replace("tls/", "tcp/"), router.lab / "robot-0.json5")
    # the same client with its credentials gets in
    router.open_raw(router.endpoint, router.lab / "robot-0.json5").close()


def test_an_agent_cannot_publish_another_robots_cmd_vel(router: Router) -> None:
    with (
        router.bus("sim", "sim") as sim,
        router.bus("robot-0") as robot0,
        router.bus("coordinator", "coordinator") as coordinator,
    ):
        k = sim.keys
        commands, awards = Inbox(), Inbox()
        sim.subscribe(k.all_robots("cmd_vel"), Twist, commands)
        sim.subscribe(k.award("*"), Award, awards)
        time.sleep(0.5)
        robot0.publish(k.robot("robot-1", "cmd_vel"), Twist(1.0, 0.5, 0.0), control=True)
        robot0.publish(k.award("robot-0"), _award("robot-0"), control=True)
        robot0.publish(k.robot("robot-0", "cmd_vel"), Twist(1.0, 0.2, 0.0), control=True)
        coordinator.publish(k.award("robot-1"), _award("robot-1"), control=True)
        # what robot-0 may send arrives, and the coordinator's award: the router is passing
        # traffic, and what robot-0 sent before it was turned away, not lost
        assert commands.wait_for(k.robot("robot-0", "cmd_vel"))
        assert awards.wait_for(k.award("robot-1"))
        time.sleep(0.5)
        assert k.robot("robot-1", "cmd_vel") not in commands.keys
        assert k.award("robot-0") not in awards.keys


def test_only_the_simulator_publishes_scans_and_robots_never_see_truth(router: Router) -> None:
    with (
        router.bus("sim", "sim") as sim,
        router.bus("robot-1") as robot1,
        router.bus("dashboard", "dashboard") as dashboard,
    ):
        k = sim.keys
        scans, robot_truth, dashboard_truth = Inbox(), Inbox(), Inbox()
        dashboard.subscribe(k.all_robots("scan"), LaserScan, scans)
        robot1.subscribe(k.all_robots("truth"), TruthPose, robot_truth)
        dashboard.subscribe(k.all_robots("truth"), TruthPose, dashboard_truth)
        time.sleep(0.5)
        robot1.publish(k.robot("robot-0", "scan"), _scan(1.0))
        sim.publish(k.robot("robot-1", "scan"), _scan(2.0))
        sim.publish(k.robot("robot-1", "truth"), TruthPose(2.0, 1.0, 1.0, 0.0))
        assert scans.wait_for(k.robot("robot-1", "scan"))
        assert dashboard_truth.wait_for(k.robot("robot-1", "truth"))
        time.sleep(0.5)
        assert k.robot("robot-0", "scan") not in scans.keys
        assert robot_truth.keys == []


def _award(robot: str) -> Award:
    return Award(1.0, 1, robot, ["t1"], np.zeros((1, 2)), np.ones((1, 2)), np.array([10.0]))


def _scan(stamp: float) -> LaserScan:
    return LaserScan(stamp, 0.0, 0.1, 0.1, 6.0, np.ones(4, dtype=np.float32))
