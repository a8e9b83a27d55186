"""The run dir's process table and the operator verbs (`fleet kill`, `respawn`, `status`, `down`)
on real files, real child processes and real signals; and once on a real `fleet up`."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from typer.testing import CliRunner

from fleet.cli import app
from fleet.rundir import (
    TABLE_NAME,
    ProcessRecord,
    RunDirError,
    RunTable,
    cmdline,
    newest_run_dir,
    process_state,
    read_table,
    write_dropped,
    write_table,
)
from fleet.supervisor.runner import descendants

ROOT = Path(__file__).resolve().parents[2]
WORLD = ROOT / "configs" / "worlds" / "small.yaml"
SLEEP = "import time; time.sleep(60)"
# A stand-in for `fleet up`: on SIGTERM it writes the report and exits, as the real one does.
FAKE_UP = (
    "import pathlib, signal, sys, time\n"
    "def stop(*_):\n"
    "    pathlib.Path(sys.argv[1], 'report.json').write_text('{}')\n"
    "    sys.exit(0)\n"
    "signal.signal(signal.SIGTERM, stop)\n"
    "print('ready', flush=True)\n"
    "time.sleep(60)\n"
)

runner = CliRunner()


def _wait_state(pid: int, argv: list[str], want: str, timeout: float = 5.0) -> str:
    deadline = time.monotonic() + timeout
    state = process_state(pid, argv)
    while state != want and time.monotonic() < deadline:
        time.sleep(0.02)
        state = process_state(pid, argv)
    return state


class Children:
    """Child processes that look like fleet processes in /proc; all killed at the end."""

    def __init__(self) -> None:
        self.procs: list[subprocess.Popen] = []

    def fleet_like(self, argv: list[str]) -> subprocess.Popen:
        """``python -c <sleep> fleet.cli *argv``: /proc shows fleet.cli followed by argv."""
        return self.start([sys.executable, "-c", SLEEP, "fleet.cli", *argv])

    def start(self, cmd: list[str], stdout: int | None = None) -> subprocess.Popen:
        proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=stdout)
        self.procs.append(proc)
        deadline = time.monotonic() + 5.0
        while cmdline(proc.pid) != cmd and time.monotonic() < deadline:
            time.sleep(0.01)  # until exec has replaced the forked test process
        return proc

    def cleanup(self) -> None:
        for proc in self.procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGCONT)
                proc.kill()
            proc.wait(5)
            if proc.stdout is not None:
                proc.stdout.close()


@pytest.fixture
def children() -> Iterator[Children]:
    c = Children()
    try:
        yield c
    finally:
        c.cleanup()


AGENT0 = ["agent", "--id", "robot-0", "--connect", "tcp/127.0.0.1:1"]
AGENT1 = ["agent", "--id", "robot-1", "--connect", "tcp/127.0.0.1:1"]
COORD = ["coordinator", "--robots", "2", "--connect", "tcp/127.0.0.1:1"]


@pytest.fixture
def fake_run(tmp_path: Path, children: Children) -> dict:
    """A run dir whose table points at live stand-ins: robot-0, the coordinator and `fleet up`
    are running; robot-1 has exited."""
    robot0 = children.fleet_like(AGENT0)
    coord = children.fleet_like(COORD)
    gone = children.fleet_like(AGENT1)
    gone.kill()
    gone.wait()
    up_cmd = [sys.executable, "-c", FAKE_UP, str(tmp_path)]
    up = children.start(up_cmd, stdout=subprocess.PIPE)
    assert up.stdout is not None and up.stdout.readline() == b"ready\n"  # it handles SIGTERM
    now = time.time()
    table = RunTable(
        fleet="test",
        endpoint="tcp/127.0.0.1:1",
        up_pid=up.pid,
        world=str(WORLD),
        processes={
            "router": ProcessRecord(gone.pid, ["router"], now, 0, "router.log"),
            "coordinator": ProcessRecord(coord.pid, COORD, now, 0, "coordinator.log"),
            "robot-0": ProcessRecord(robot0.pid, AGENT0, now, 0, "robot-0.log"),
            "robot-1": ProcessRecord(gone.pid, AGENT1, now, 2, "robot-1.log"),
        },
        up_cmdline=up_cmd,
    )
    write_table(tmp_path, table)
    return {"dir": tmp_path, "robot0": robot0, "coord": coord, "up": up, "gone": gone}


# ---- the process table ------------------------------------------------------------------------


def test_table_round_trip(tmp_path: Path) -> None:
    table = RunTable(
        "f",
        "tcp/127.0.0.1:7447",
        123,
        "/w.yaml",
        {"robot-0": ProcessRecord(456, AGENT0, 1.5, 1, "robot-0.log")},
        ["python", "fleet", "up"],
    )
    write_table(tmp_path, table)
    assert read_table(tmp_path) == table
    assert read_table(tmp_path).robots() == ["robot-0"]
    raw = json.loads((tmp_path / TABLE_NAME).read_text())
    assert raw["processes"]["robot-0"] == {
        "pid": 456,
        "argv": AGENT0,
        "started": 1.5,
        "restarts": 1,
        "log": "robot-0.log",
    }


def test_table_write_is_atomic_and_leaves_no_temp_files(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    old = RunTable("f", "tcp/127.0.0.1:1", 1, "w", {})
    write_table(tmp_path, old)
    new = RunTable("f", "tcp/127.0.0.1:1", 2, "w", {})
    replaced: list[tuple[str, str]] = []
    real_replace = os.replace

    def replace(src: str, dst: Path) -> None:
        # When the new table takes the old one's name it is already complete on disk.
        assert json.loads(Path(src).read_text())["up_pid"] == 2
        assert json.loads(Path(dst).read_text())["up_pid"] == 1
        replaced.append((src, str(dst)))
        real_replace(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    write_table(tmp_path, new)
    assert replaced and replaced[0][1] == str(tmp_path / TABLE_NAME)
    assert read_table(tmp_path).up_pid == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == [TABLE_NAME]


def test_table_errors_name_the_path(tmp_path: Path) -> None:
    with pytest.raises(RunDirError, match=f"no such run dir: {tmp_path / 'nope'}"):
        read_table(tmp_path / "nope")
    with pytest.raises(RunDirError, match=rf"no fleet was started in {tmp_path} \(no processes"):
        read_table(tmp_path)
    (tmp_path / TABLE_NAME).write_text("{not json")
    with pytest.raises(RunDirError, match=f"{tmp_path / TABLE_NAME} is not valid JSON"):
        read_table(tmp_path)
    (tmp_path / TABLE_NAME).write_text(
        json.dumps({"fleet": "f", "endpoint": "e", "up_pid": 1, "world": "w", "processes": {}})
    )
    assert read_table(tmp_path).processes == {}
    bad = {"pid": "12", "argv": [], "started": 0, "restarts": 0, "log": "x.log"}
    (tmp_path / TABLE_NAME).write_text(
        json.dumps(
            {"fleet": "f", "endpoint": "e", "up_pid": 1, "world": "w", "processes": {"r": bad}}
        )
    )
    with pytest.raises(RunDirError, match=r"field processes\.r\.pid must be int"):
        read_table(tmp_path)
    (tmp_path / TABLE_NAME).write_text(json.dumps({"fleet": "f", "processes": {}}))
    with pytest.raises(RunDirError, match="missing field endpoint"):
        read_table(tmp_path)


def test_newest_run_dir_is_the_newest_with_a_table(tmp_path: Path) -> None:
    with pytest.raises(RunDirError, match=f"{tmp_path / 'runs'}/ does not exist"):
        newest_run_dir(tmp_path / "runs")
    runs = tmp_path / "runs"
    runs.mkdir()
    with pytest.raises(RunDirError, match=f"no fleet was started under {runs}/"):
        newest_run_dir(runs)
    for i, name in enumerate(("a", "b", "c")):
        (runs / name).mkdir()
        write_table(runs / name, RunTable("f", "e", 1, "w", {}))
        t = 1_000_000 + i * 10
        os.utime(runs / name / TABLE_NAME, (t, t))
    (runs / "d").mkdir()  # the newest dir, but no fleet in it
    (runs / "d" / "up.log").write_text("x")
    assert newest_run_dir(runs) == runs / "c"


def test_process_state_of_a_real_child(children: Children) -> None:
    argv = ["agent", "--id", "robot-x"]
    proc = children.fleet_like(argv)
    assert process_state(proc.pid, argv) == "running"
    # Another program at that pid (or another robot) is not ours.
    assert process_state(proc.pid, ["agent", "--id", "robot-y"]) == "gone"
    os.kill(proc.pid, signal.SIGSTOP)
    assert _wait_state(proc.pid, argv, "stopped") == "stopped"
    os.kill(proc.pid, signal.SIGCONT)
    assert _wait_state(proc.pid, argv, "running") == "running"
    os.kill(proc.pid, signal.SIGKILL)
    assert _wait_state(proc.pid, argv, "zombie") == "zombie"
    proc.wait()
    assert process_state(proc.pid, argv) == "gone"


def test_process_state_matches_a_whole_command_line(children: Children) -> None:
    cmd = [sys.executable, "-c", SLEEP, "up", "--robots", "2"]
    proc = children.start(cmd)
    assert process_state(proc.pid, cmd) == "running"
    assert process_state(proc.pid, ["up", "--robots", "2"]) == "gone"  # no fleet.cli in it


# ---- the launcher ------------------------------------------------------------------------------


def test_launcher_records_restarts_and_appends_to_the_log(tmp_path: Path) -> None:
    from fleet.supervisor.launcher import Launcher, free_port

    tables: list[dict[str, ProcessRecord]] = []
    launcher = Launcher(tmp_path, on_change=tables.append)
    try:
        first = launcher.start("x", ["--help"])
        assert first.wait(30) == 0
        assert tables[-1]["x"] == ProcessRecord(
            first.pid, ["--help"], tables[-1]["x"].started, 0, "x.log"
        )
        with pytest.raises(ValueError, match="x was started already"):
            launcher.start("x", ["--help"])
        with pytest.raises(ValueError, match="no process 'y'"):
            launcher.restart("y", ["--help"])
        router = launcher.start("r", ["router", "--listen", f"tcp/127.0.0.1:{free_port()}"])
        with pytest.raises(RuntimeError, match=rf"r is alive \(pid {router.pid}\); kill it first"):
            launcher.restart("r", ["--help"])
        size = (tmp_path / "x.log").stat().st_size
        assert size > 0
        again = launcher.restart("x", ["--version-is-no-option"])
        assert again.wait(30) == 2
        assert tables[-1]["x"].pid == again.pid and tables[-1]["x"].restarts == 1
        assert tables[-1]["x"].argv == ["--version-is-no-option"]
        log = (tmp_path / "x.log").read_bytes()
        assert b"Usage" in log[:size] and b"No such option" in log[size:]  # both runs kept
    finally:
        launcher.stop_all()
    with pytest.raises(RuntimeError, match="stopping"):
        launcher.restart("x", ["--help"])


# ---- fleet kill ---------------------------------------------------------------------------------


def test_kill_stop_cont_kill_a_real_process(fake_run: dict) -> None:
    d, pid = str(fake_run["dir"]), fake_run["robot0"].pid
    result = runner.invoke(app, ["kill", "robot-0", "--signal", "STOP", "--run-dir", d])
    assert result.exit_code == 0, result.output
    assert f"sent SIGSTOP to robot-0 (pid {pid}" in result.stdout
    assert _wait_state(pid, AGENT0, "stopped") == "stopped"
    result = runner.invoke(app, ["kill", "robot-0", "-s", "cont", "--run-dir", d])
    assert result.exit_code == 0, result.output
    assert _wait_state(pid, AGENT0, "running") == "running"
    result = runner.invoke(app, ["kill", "robot-0", "--signal", "KILL", "--run-dir", d])
    assert result.exit_code == 0, result.output
    assert fake_run["robot0"].wait(5) == -signal.SIGKILL
    assert process_state(pid, AGENT0) == "gone"
    result = runner.invoke(app, ["kill", "robot-0", "--run-dir", d])
    assert result.exit_code == 2
    assert f"error: robot-0 (pid {pid}) has already exited" in result.stderr


def test_kill_terminates_the_coordinator_by_default(fake_run: dict) -> None:
    result = runner.invoke(app, ["kill", "coordinator", "--run-dir", str(fake_run["dir"])])
    assert result.exit_code == 0, result.output
    assert fake_run["coord"].wait(5) == -signal.SIGTERM


def test_kill_unknown_robot_lists_the_robots(fake_run: dict) -> None:
    d = fake_run["dir"]
    for name in ("robot-9", "router"):
        result = runner.invoke(app, ["kill", name, "--run-dir", str(d)])
        assert result.exit_code == 2
        assert (
            f"error: no robot '{name}' in {d}; robots: robot-0, robot-1; or 'coordinator'"
            in result.stderr
        )
    assert process_state(fake_run["robot0"].pid, AGENT0) == "running"


def test_verbs_without_a_run_dir_fail_clearly(tmp_path: Path) -> None:
    for args in (["kill", "robot-0"], ["respawn", "robot-0"], ["status"], ["down"]):
        result = runner.invoke(app, [*args, "--run-dir", str(tmp_path / "none")])
        assert result.exit_code == 2, args
        assert f"error: no such run dir: {tmp_path / 'none'}" in result.stderr
    result = runner.invoke(app, ["status", "--run-dir", str(tmp_path)])
    assert result.exit_code == 2
    assert f"no fleet was started in {tmp_path} (no processes.json)" in result.stderr


def test_default_run_dir_is_the_newest_under_runs(
    fake_run: dict, tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch
) -> None:
    cwd = tmp_path_factory.mktemp("cwd")
    monkeypatch.chdir(cwd)
    result = runner.invoke(app, ["status"])
    assert result.exit_code == 2 and "runs/ does not exist" in result.stderr
    (cwd / "runs").mkdir()
    (cwd / "runs" / "now").symlink_to(fake_run["dir"])
    result = runner.invoke(app, ["status", "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["run_dir"] == "runs/now"


# ---- fleet respawn ------------------------------------------------------------------------------


def test_respawn_refuses_a_live_process(fake_run: dict) -> None:
    d, pid = str(fake_run["dir"]), fake_run["robot0"].pid
    result = runner.invoke(app, ["respawn", "robot-0", "--run-dir", d])
    assert result.exit_code == 2
    assert f"error: robot-0 is alive (pid {pid}); kill it first" in result.stderr
    os.kill(pid, signal.SIGSTOP)
    assert _wait_state(pid, AGENT0, "stopped") == "stopped"
    result = runner.invoke(app, ["respawn", "robot-0", "--run-dir", d])
    assert result.exit_code == 2 and "robot-0 is alive" in result.stderr


def test_respawn_when_fleet_up_is_gone(fake_run: dict) -> None:
    fake_run["up"].kill()
    fake_run["up"].wait()
    result = runner.invoke(app, ["respawn", "robot-1", "--run-dir", str(fake_run["dir"])])
    assert result.exit_code == 2
    pid = fake_run["up"].pid
    assert f"error: is fleet up still running? its pid {pid} is gone" in result.stderr


# ---- fleet status -------------------------------------------------------------------------------

SCHEMA = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT);
CREATE TABLE tasks (id TEXT PRIMARY KEY, parent TEXT, area_m2 REAL, time_s REAL, path BLOB,
                    cells TEXT, state TEXT, owner TEXT, position INTEGER, reverse INTEGER,
                    swept BLOB, created_wall REAL, done_wall REAL);
CREATE TABLE robots (id TEXT PRIMARY KEY, liveness TEXT, state TEXT, task TEXT, progress REAL,
                     heartbeat_wall REAL, restarts INTEGER, award_seq INTEGER, acked_seq INTEGER,
                     x REAL, y REAL);
CREATE TABLE events (seq INTEGER PRIMARY KEY AUTOINCREMENT, wall REAL, sim REAL, kind TEXT,
                     robot TEXT, task TEXT, detail TEXT);
"""


def _write_state(path: Path, now: float, phase: str = '"cleaning"') -> None:
    """A coordinator state file; meta values are JSON, as the coordinator writes them."""
    con = sqlite3.connect(path)
    con.executescript(SCHEMA)
    con.executemany("INSERT INTO meta VALUES (?, ?)", [("phase", phase), ("expected_robots", "2")])
    tasks = [("t0", "done"), ("t1", "assigned"), ("t2", "assigned"), ("t3", "open")]
    tasks += [("t4", "replaced"), ("t5", "done"), ("t6", "done")]
    con.executemany("INSERT INTO tasks (id, state) VALUES (?, ?)", tasks)
    con.executemany(
        "INSERT INTO robots (id, liveness, state, task, progress, heartbeat_wall, restarts) "
        "VALUES (?, ?, ?, ?, ?, ?, ?)",
        [
            ("robot-0", "alive", "cleaning", "t1", 0.25, now - 1.0, 0),
            ("robot-1", "lost", "idle", None, 0.0, now - 30.0, 2),
        ],
    )
    con.commit()
    con.close()


def test_status_json_reads_the_table_and_the_coordinator_state(fake_run: dict) -> None:
    d = fake_run["dir"]
    _write_state(d / "coordinator.sqlite", time.time())
    result = runner.invoke(app, ["status", "--json", "--run-dir", str(d)])
    assert result.exit_code == 0, result.output
    s = json.loads(result.stdout)
    assert s["run_dir"] == str(d) and s["fleet"] == "test"
    assert s["up"] == {
        "pid": fake_run["up"].pid,
        "state": "running",
        "malformed": None,
        "implausible": None,
    }
    robot0 = s["processes"]["robot-0"]
    assert robot0["pid"] == fake_run["robot0"].pid and robot0["state"] == "running"
    assert robot0["restarts"] == 0 and robot0["log"] == str(d / "robot-0.log")
    assert s["processes"]["robot-1"]["state"] == "gone"
    assert s["processes"]["robot-1"]["restarts"] == 2
    assert s["processes"]["coordinator"]["state"] == "running"
    coord = s["coordinator"]
    assert s["coordinator_note"] == ""
    assert coord["phase"] == "cleaning" and coord["expected_robots"] == 2
    assert coord["tasks"] == {"open": 1, "assigned": 2, "done": 3}
    r0, r1 = coord["robots"]["robot-0"], coord["robots"]["robot-1"]
    assert (r0["liveness"], r0["state"], r0["task"], r0["progress"]) == (
        "alive",
        "cleaning",
        "t1",
        0.25,
    )
    assert 0.5 <= r0["heartbeat_age_s"] < 10.0
    assert 29.5 <= r1["heartbeat_age_s"] < 40.0
    assert (r1["liveness"], r1["task"], r1["restarts"]) == ("lost", None, 2)
    # The status never writes the coordinator's file.
    assert sorted(p.name for p in d.glob("coordinator.sqlite*")) == ["coordinator.sqlite"]


def test_status_without_the_coordinator_state(fake_run: dict) -> None:
    d = str(fake_run["dir"])
    result = runner.invoke(app, ["status", "--json", "--run-dir", d])
    assert result.exit_code == 0, result.output
    s = json.loads(result.stdout)
    assert s["coordinator"] is None and s["coordinator_note"] == "not written yet"
    assert s["processes"]["robot-0"]["state"] == "running"
    result = runner.invoke(app, ["status", "--run-dir", d])
    assert result.exit_code == 0, result.output
    assert "coordinator state: not written yet" in result.stdout
    lines = result.stdout.splitlines()
    robot0 = next(line for line in lines if line.startswith("robot-0 "))
    assert robot0.split() == ["robot-0", str(fake_run["robot0"].pid), "running", "0", "-", "-"]


def test_status_shows_the_messages_each_process_dropped(fake_run: dict) -> None:
    d = fake_run["dir"]
    write_dropped(d, {"coordinator": (2, 5), "robot-0": (1, None), "up": (0, 0)})
    result = runner.invoke(app, ["status", "--json", "--run-dir", str(d)])
    s = json.loads(result.stdout)
    coord, robot0 = s["processes"]["coordinator"], s["processes"]["robot-0"]
    assert (coord["malformed"], coord["implausible"]) == (2, 5)
    assert (robot0["malformed"], robot0["implausible"]) == (1, None)
    assert s["processes"]["robot-1"]["malformed"] is None
    assert (s["up"]["malformed"], s["up"]["implausible"]) == (0, 0)
    result = runner.invoke(app, ["status", "--run-dir", str(d)])
    lines = result.stdout.splitlines()
    assert lines[1].split() == ["process", "pid", "state", "restarts", "malformed", "implausible"]
    row = next(line for line in lines if line.startswith("coordinator "))
    assert row.split()[-2:] == ["2", "5"]


def test_status_plain_text_shows_the_robots(fake_run: dict) -> None:
    d = fake_run["dir"]
    _write_state(d / "coordinator.sqlite", time.time(), phase="cleaning")  # plain text too
    result = runner.invoke(app, ["status", "--run-dir", str(d)])
    assert result.exit_code == 0, result.output
    assert "coordinator: phase cleaning; tasks open 1, assigned 2, done 3" in result.stdout
    row = next(line for line in result.stdout.splitlines()[::-1] if line.startswith("robot-1 "))
    assert row.split()[:4] == ["robot-1", "lost", "idle", "-"]


# ---- fleet down ---------------------------------------------------------------------------------


def test_down_stops_fleet_up_and_names_the_report(fake_run: dict) -> None:
    d = fake_run["dir"]
    result = runner.invoke(app, ["down", "--run-dir", str(d), "--timeout", "10"])
    assert result.exit_code == 0, result.output
    assert f"sent SIGTERM to fleet up (pid {fake_run['up'].pid})" in result.stdout
    assert f"report: {d / 'report.json'}" in result.stdout
    assert fake_run["up"].wait(5) == 0
    result = runner.invoke(app, ["down", "--run-dir", str(d)])
    assert result.exit_code == 2
    assert f"error: fleet up (pid {fake_run['up'].pid}) is not running" in result.stderr


# ---- on a real fleet ----------------------------------------------------------------------------


def _fleet(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "fleet.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
    )


@pytest.mark.integration
@pytest.mark.timeout(120)
def test_kill_status_respawn_down_on_a_real_fleet(tmp_path: Path) -> None:
    d = tmp_path / "run"
    opts = ["--headless", "--speed", "0", "--run-dir", str(d)]
    up = subprocess.Popen(
        [sys.executable, "-m", "fleet.cli", "up", "--robots", "1", "--world", str(WORLD), *opts],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        cwd=ROOT,
    )
    children: set[int] = set()
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            children |= set(descendants(up.pid))
            log = d / "robot-0.log"
            if (d / TABLE_NAME).exists() and log.exists() and b"spawned" in log.read_bytes():
                break  # the robot is in the world
            assert up.poll() is None, up.stdout.read().decode() if up.stdout else ""
            time.sleep(0.2)
        table = read_table(d)
        assert table.up_pid == up.pid and set(table.processes) == {
            "router",
            "sim",
            "coordinator",
            "robot-0",
        }
        old = table.processes["robot-0"]
        assert "--state-dir" in old.argv and str(d / "robot-0") in old.argv
        assert str(d / "coordinator.sqlite") in table.processes["coordinator"].argv
        children |= set(descendants(up.pid))

        killed = _fleet("kill", "robot-0", "--signal", "KILL", "--run-dir", str(d))
        assert killed.returncode == 0, killed.stderr
        assert _wait_state(old.pid, old.argv, "gone") == "gone"
        status = _fleet("status", "--json", "--run-dir", str(d))
        assert status.returncode == 0, status.stderr
        procs = json.loads(status.stdout)["processes"]
        assert procs["robot-0"]["state"] == "gone"
        assert procs["sim"]["state"] == "running" and procs["router"]["state"] == "running"

        before = (d / "robot-0.log").read_bytes()
        respawned = _fleet("respawn", "robot-0", "--run-dir", str(d))
        assert respawned.returncode == 0, respawned.stderr
        new = read_table(d).processes["robot-0"]
        assert new.restarts == 1 and new.pid != old.pid
        assert new.argv == [*old.argv, "--respawn"]
        assert (d / "robot-0.log").read_bytes().startswith(before)  # appended, not replaced
        assert process_state(new.pid, new.argv) in ("running", "stopped")
        children |= set(descendants(up.pid))
        refused = _fleet("respawn", "robot-0", "--run-dir", str(d))
        assert refused.returncode == 2 and f"alive (pid {new.pid})" in refused.stderr
        assert up.poll() is None

        down = _fleet("down", "--run-dir", str(d), "--timeout", "60", timeout=90)
        assert down.returncode == 0, down.stdout + down.stderr
        assert up.wait(10) == 0
        assert json.loads((d / "report.json").read_text())["status"] == "stopped"
        assert f"report: {d / 'report.json'}" in down.stdout
    finally:
        if up.poll() is None:
            up.send_signal(signal.SIGTERM)
            try:
                up.wait(30)
            except subprocess.TimeoutExpired:
                up.kill()
                up.wait()
        time.sleep(0.5)
        left = [p for p in children if Path(f"/proc/{p}").exists()]
        for p in left:
            with contextlib.suppress(ProcessLookupError):
                os.kill(p, signal.SIGKILL)
    assert not left, f"orphans: {left}"


def test_respawns_asked_on_another_thread_are_made_by_the_main_thread() -> None:
    import threading
    from concurrent import futures

    from fleet.supervisor.respawn import MainThreadCalls

    calls = MainThreadCalls()
    seen: list[object] = []
    asker = threading.Thread(
        target=lambda: seen.append(calls.call(threading.current_thread, timeout=5.0))
    )
    asker.start()
    deadline = time.monotonic() + 5.0
    while not seen and time.monotonic() < deadline:
        calls.run_pending()
        time.sleep(0.01)
    asker.join()
    assert seen == [threading.main_thread()]
    with pytest.raises(futures.TimeoutError):
        calls.call(lambda: None, timeout=0.05)


def test_up_refuses_a_run_dir_that_holds_an_earlier_run(tmp_path: Path) -> None:
    (tmp_path / "coordinator.sqlite").write_bytes(b"")
    result = runner.invoke(app, ["up", "--run-dir", str(tmp_path), "--headless"])
    assert result.exit_code == 2
    assert "holds an earlier run" in result.output
    assert str(tmp_path) in result.output
