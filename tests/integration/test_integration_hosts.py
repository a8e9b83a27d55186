"""A fleet spread over hosts: the router, the simulator, the coordinator and each agent in a
Linux network namespace of its own, each joined to the router's namespace by a veth pair and
to nothing else, so the processes reach each other only through the router's TCP address.
A small fleet runs, and once a task is done the router is killed and started again, then one
robot's link goes down for a while: every process must reconnect by itself (a robot is lost to
the coordinator, then rejoins), and each robot must finish a task after that, its award and its
report carried by the router. That the job then finishes, its lost robots' work sold again, is
the single-host recovery tests'.

Needs root (or CAP_NET_ADMIN and CAP_SYS_ADMIN) and iproute2; skips with the reason otherwise.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from fleet.sim_guard import SimGuard
from fleet.supervisor.runner import read_events

pytestmark = [pytest.mark.integration, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[2]
WORLD = str(ROOT / "configs" / "worlds" / "small.yaml")
PORT = 7447
ROBOTS = 2
# the router's side of link i is 10.213.i.1, the host's 10.213.i.2
SUBNET = "10.213.{}.{}"
# wall seconds the router, then a robot's link, stay down (the target: processes reconnect when
# the router is back within 10)
DOWN_S = 5.0
# the run's guard (fleet.sim_guard.SimGuard): past RUN_TIMEOUT_S wall seconds it waits on while
# the coordinator's sim clock (its events' stamps) moves, up to RUN_SIM_S sim seconds from the
# start, and gives up once no event has moved it for STALL_S wall seconds
RUN_TIMEOUT_S = 400.0
RUN_SIM_S = 900.0
STALL_S = 120.0


def _ip(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)


class Hosts:
    """Network namespaces in a star: a hub for the router and one per host, each joined to
    the hub by a veth pair on a subnet of its own; the hub does not forward between them."""

    def __init__(self, tag: str) -> None:
        self.tag = tag
        self.hub = f"fl{tag}hub"
        # name → (namespace, the router's address from it, its end of the link)
        self.hosts: dict[str, tuple[str, str, str]] = {}
        self.namespaces: list[str] = []

    def _add(self, ns: str) -> None:
        done = _ip("netns", "add", ns)
        if done.returncode != 0:
            raise OSError(f"ip netns add {ns}: {done.stderr.strip()}")
        self.namespaces.append(ns)
        self._check(_ip("-n", ns, "link", "set", "lo", "up"))

    @staticmethod
    def _check(done: subprocess.CompletedProcess) -> None:
        if done.returncode != 0:
            raise OSError(f"{' '.join(done.args)}: {done.stderr.strip()}")

    def make_hub(self) -> None:
        self._add(self.hub)

    def add_host(self, name: str) -> str:
        """A namespace for ``name`` linked to the hub; returns the router's address from it."""
        i = len(self.hosts) + 1
        ns = f"fl{self.tag}h{i}"
        self._add(ns)
        hub_end, host_end = f"fl{self.tag}a{i}", f"fl{self.tag}b{i}"
        self._check(_ip("link", "add", hub_end, "type", "veth", "peer", "name", host_end))
        self._check(_ip("link", "set", hub_end, "netns", self.hub))
        self._check(_ip("link", "set", host_end, "netns", ns))
        for where, dev, host in ((self.hub, hub_end, 1), (ns, host_end, 2)):
            self._check(_ip("-n", where, "addr", "add", f"{SUBNET.format(i, host)}/24", "dev", dev))
            self._check(_ip("-n", where, "link", "set", dev, "up"))
        router = SUBNET.format(i, 1)
        self.hosts[name] = (ns, router, host_end)
        return router

    def set_link(self, name: str, up: bool) -> None:
        """Take ``name``'s link to the router down or bring it up again."""
        ns, _, dev = self.hosts[name]
        self._check(_ip("-n", ns, "link", "set", dev, "up" if up else "down"))

    def address(self, name: str) -> str:
        """The host's own address on its link."""
        return self.hosts[name][1].rsplit(".", 1)[0] + ".2"

    def remove(self) -> None:
        for ns in reversed(self.namespaces):
            _ip("netns", "del", ns)  # its veth ends go with it


@pytest.fixture
def hosts() -> Iterator[Hosts]:
    if sys.platform != "linux":
        pytest.skip("network namespaces are Linux only")
    if shutil.which("ip") is None:
        pytest.skip("iproute2's `ip` is not installed")
    h = Hosts(str(os.getpid() % 100000))
    try:
        h.make_hub()
    except OSError as e:
        h.remove()
        pytest.skip(f"cannot make a network namespace here (needs root or CAP_SYS_ADMIN): {e}")
    try:
        yield h
    finally:
        h.remove()


class Processes:
    """Fleet processes started in namespaces, each logging to its own file."""

    def __init__(self, log_dir: Path) -> None:
        self.log_dir = log_dir
        self.procs: dict[str, subprocess.Popen] = {}

    def start(self, name: str, ns: str, argv: list[str]) -> subprocess.Popen:
        log = open(self.log_dir / f"{name}.log", "ab")  # noqa: SIM115 - closed with the process
        cmd = ["ip", "netns", "exec", ns, sys.executable, "-m", "fleet.cli", *argv]
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, cwd=ROOT)
        log.close()
        self.procs[name] = proc
        return proc

    def logs(self) -> str:
        return "\n".join(
            f"--- {p.name}\n{p.read_text(errors='replace')[-1500:]}"
            for p in sorted(self.log_dir.glob("*.log"))
        )

    def stop_all(self) -> None:
        for proc in self.procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        for proc in self.procs.values():
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def _phase(state: Path) -> str | None:
    if not state.exists():
        return None
    try:
        db = sqlite3.connect(f"file:{state}?mode=ro", uri=True, timeout=5)
        try:
            row = db.execute("SELECT value FROM meta WHERE key = 'phase'").fetchone()
            tasks = db.execute("SELECT state, COUNT(*) FROM tasks GROUP BY state").fetchall()
        finally:
            db.close()
    except sqlite3.OperationalError:
        return None
    if row is None:
        return None
    phase = json.loads(row[0])
    return "cleaning-with-done-tasks" if phase == "cleaning" and dict(tasks).get("done") else phase


def _unreachable_from(h: Hosts, name: str, address: str) -> str:
    """What connecting from ``name``'s namespace to ``address`` says (expected: an error)."""
    probe = (
        "import socket, sys\n"
        "try:\n"
        f"    socket.create_connection(({address!r}, {PORT}), timeout=2)\n"
        "    print('connected')\n"
        "except OSError as e:\n"
        "    print(type(e).__name__, e)\n"
    )
    ns = h.hosts[name][0]
    done = subprocess.run(
        ["ip", "netns", "exec", ns, sys.executable, "-c", probe],
        capture_output=True,
        text=True,
        timeout=30,
    )
    return done.stdout.strip()


def _all_running(procs: Processes) -> None:
    for name, proc in procs.procs.items():
        assert proc.poll() is None, f"{name} exited\n{procs.logs()}"


def _sim_clock(state: Path) -> Callable[[], float]:
    """The sim time as the coordinator's state file has heard it: its latest event's stamp."""
    return lambda: max((float(e["sim"]) for e in read_events(state)), default=0.0)


def _wait_for_rejoin(
    state: Path, robots: list[str], since: float, guard: SimGuard, procs: Processes
) -> float:
    """Until each of ``robots`` has been lost and has rejoined after wall time ``since``;
    returns the wall time of the last rejoin."""
    while True:
        events = [e for e in read_events(state) if e["wall"] >= since]
        kinds = {r: [e["kind"] for e in events if e["robot"] == r] for r in robots}
        if all("lost" in k and "rejoined" in k[k.index("lost") :] for k in kinds.values()):
            return max(e["wall"] for e in events if e["kind"] == "rejoined")
        assert not guard.expired(), f"not lost and rejoined: {kinds}\n{procs.logs()}"
        _all_running(procs)
        time.sleep(0.5)


def _done_since(state: Path, robots: list[str], since: float) -> bool:
    """Whether each of ``robots`` has finished a task after wall time ``since``."""
    done = {e["robot"] for e in read_events(state) if e["wall"] > since and e["kind"] == "done"}
    return set(robots) <= done


@pytest.mark.timeout(3 * RUN_TIMEOUT_S)
def test_a_fleet_across_hosts_finishes_through_a_router_restart_and_a_link_down(
    hosts: Hosts, tmp_path: Path
) -> None:
    names = ["sim", "coordinator", *(f"robot-{i}" for i in range(ROBOTS))]
    routers = {name: hosts.add_host(name) for name in names}
    # the hosts reach the router's port, and nothing of each other
    assert "Error" in _unreachable_from(hosts, "robot-0", hosts.address("robot-1"))
    assert "Error" in _unreachable_from(hosts, "sim", hosts.address("coordinator"))

    state = tmp_path / "coordinator.sqlite"
    procs = Processes(tmp_path)
    router_argv = ["router", "--listen", f"tcp/0.0.0.0:{PORT}"]
    try:
        procs.start("router", hosts.hub, router_argv)
        for name in names:
            connect = ["--connect", f"tcp/{routers[name]}:{PORT}"]
            if name == "sim":
                # four times real time: two robots' job (250-300 s of sim) far outlasts the
                # router's restart and the link's fall (done by about 60 s of sim)
                argv = ["sim", "--world", WORLD, "--speed", "4", *connect]
            elif name == "coordinator":
                argv = ["coordinator", "--robots", str(ROBOTS), "--world", WORLD]
                argv += ["--state", str(state), *connect]
            else:
                index = name.rsplit("-", 1)[1]
                argv = ["agent", "--id", name, "--start-index", index, "--world", WORLD]
                argv += ["--state-dir", str(tmp_path / name), *connect]
            procs.start(name, hosts.hosts[name][0], argv)

        guard = SimGuard(_sim_clock(state), RUN_TIMEOUT_S, STALL_S, RUN_SIM_S)
        while _phase(state) != "cleaning-with-done-tasks":
            assert not guard.expired(), f"no task done in time\n{procs.logs()}"
            _all_running(procs)
            time.sleep(0.5)

        router = procs.procs["router"]
        killed_wall = time.time()
        router.kill()
        router.wait()
        time.sleep(DOWN_S)
        back = time.time()
        procs.start("router", hosts.hub, router_argv)
        rejoined = _wait_for_rejoin(state, names[2:], killed_wall, guard, procs)
        print(f"router down {DOWN_S:g} s: every robot rejoined {rejoined - back:.1f} s after")
        assert _phase(state) != "done", f"the job ended before the link went down\n{procs.logs()}"
        link_down_wall = time.time()
        hosts.set_link("robot-1", up=False)
        time.sleep(DOWN_S)
        back = time.time()
        hosts.set_link("robot-1", up=True)
        rejoined = _wait_for_rejoin(state, ["robot-1"], link_down_wall, guard, procs)
        print(f"link down {DOWN_S:g} s: robot-1 rejoined {rejoined - back:.1f} s after")

        # both robots work on through the router: each finishes a task after the link is back
        while not _done_since(state, names[2:], rejoined):
            assert not guard.expired(), f"no task done after the rejoins\n{procs.logs()}"
            _all_running(procs)
            time.sleep(0.5)
    finally:
        procs.stop_all()
