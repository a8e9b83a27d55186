"""The live view: its model fed with encoded bus messages (as recorded) or over a live bus,
drawn headless; and its kill key on a real process with a real signal."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from fleet.bus import Bus, open_router
from fleet.dashboard.model import BusFeed, FleetWatcher, RateMeter
from fleet.dashboard.term import DOWN, KILL, QUIT, UP, ViewControl, parse_keys
from fleet.dashboard.view import LOST_MARK, WALL, header, heading_arrow, plain, screen
from fleet.floor_map import pack_grid
from fleet.plausible import StampWatch
from fleet.protocol import (
    Clock,
    Collision,
    FleetEvent,
    FleetState,
    Heartbeat,
    Intent,
    Keys,
    Message,
    Plan,
    RobotStatus,
    TruthPose,
    decode,
    key_class,
)
from fleet.rundir import ProcessRecord, RunTable, cmdline, write_table
from fleet.supervisor.launcher import free_port
from fleet.supervisor.ops import ProcessActions
from planners.grid import GridMap

KEYS = Keys()
RES = 0.05
# a 4 m × 3 m room with walls one cell thick, drawn 40 × 15 characters: 0.1 m per column,
# 0.2 m per row, x from 0, y from 3 m at the top row
WIDTH, HEIGHT = 40, 15


def _room() -> GridMap:
    occupied = np.zeros((60, 80), dtype=bool)
    occupied[0, :] = occupied[-1, :] = occupied[:, 0] = occupied[:, -1] = True
    return GridMap(occupied, np.zeros_like(occupied), RES, (0.0, 0.0))


def _recorded(msg: Message) -> Message:
    """The message as a subscriber gets it: encoded, then decoded."""
    return decode(msg.encode(), type(msg))


def _watcher() -> FleetWatcher:
    w = FleetWatcher()
    w.on_floor(_recorded(pack_grid(_room())))
    for rid in ("robot-0", "robot-1"):
        status = RobotStatus(10.0, "driving", "t03", 0.4, 3, 10, 4.2)
        w.on_status(KEYS.robot(rid, "status"), _recorded(status))
        w.on_alive(rid, True)
    return w


def _map_lines(w: FleetWatcher) -> list[str]:
    from fleet.dashboard.view import render_map

    return plain(render_map(w.snapshot(), WIDTH, HEIGHT)).splitlines()


def test_the_map_shows_each_robot_where_its_pose_says() -> None:
    w = _watcher()
    w.on_truth(KEYS.robot("robot-0", "truth"), _recorded(TruthPose(10.0, 1.05, 2.1, 0.0)))
    w.on_truth(KEYS.robot("robot-1", "truth"), _recorded(TruthPose(10.0, 3.05, 0.5, np.pi / 2)))
    lines = _map_lines(w)
    assert len(lines) == HEIGHT and all(len(line) == WIDTH for line in lines)
    assert lines[0] == WALL * WIDTH and lines[-1] == WALL * WIDTH
    # x 1.05 m → column 10; y 2.1 m → row (3 - 2.1) / 0.2 = 4.5 → 4; its number after it
    assert lines[4][10:12] == heading_arrow(0.0) + "0" == "→0"
    # x 3.05 m → column 30; y 0.5 m → row 12
    assert lines[12][30:32] == "↑1"
    w.on_truth(KEYS.robot("robot-0", "truth"), _recorded(TruthPose(11.0, 2.05, 1.1, np.pi)))
    lines = _map_lines(w)
    assert "→0" not in "".join(lines)
    assert lines[9][20:22] == "←0"


def test_a_lost_robot_shows_as_lost_in_the_table_and_on_the_map() -> None:
    w = _watcher()
    for rid, x in (("robot-0", 1.05), ("robot-1", 2.05)):
        w.on_truth(KEYS.robot(rid, "truth"), TruthPose(10.0, x, 1.5, 0.0))
    w.on_fleet("", _recorded(FleetState(10.0, "cleaning", ["robot-0", "robot-1"], [], ["robot-1"])))
    w.on_event("", _recorded(FleetEvent(10.0, 0.0, "awarded", "robot-0", "t04", "")))
    w.on_event("", _recorded(FleetEvent(11.0, 0.0, "lost", "robot-1", "", "token gone")))
    text = plain(screen(w.snapshot(), 100, 40))
    rows = {rid: next(ln for ln in text.splitlines() if f" {rid} " in ln) for rid in ("robot-0",)}
    rows["robot-1"] = next(ln for ln in text.splitlines() if " robot-1 " in ln and "t03" in ln)
    assert rows["robot-1"].split()[2] == "lost"
    assert rows["robot-0"].split()[2] == "alive"
    assert LOST_MARK + "1" in text and "→0" in text
    assert "token gone" in text and "awarded" not in text
    assert w.take_events()[0].endswith("token gone")
    assert w.take_events() == []
    assert "lost=robot-1" in w.line(5.0)


def test_an_agent_whose_liveliness_token_went_is_lost_before_the_coordinator_says_so() -> None:
    w = _watcher()
    w.on_alive("robot-0", False)
    rows = {r.rid: r.liveness for r in w.snapshot().robots}
    assert rows == {"robot-0": "lost", "robot-1": "alive"}


def test_contacts_and_given_up_waypoints_are_events_and_the_eta_follows_the_tasks() -> None:
    w = _watcher()
    w.on_collision("", Collision(12.0, "wall", "robot-0", "", 1.0, 2.0))
    w.on_status(
        KEYS.robot("robot-1", "status"),
        RobotStatus(13.0, "driving", "t03", 0.5, 4, 10, 5.0, skipped=2),
    )
    texts = [e.text for e in w.snapshot().events]
    assert any("contact" in t and "robot-0" in t for t in texts)
    assert any("gave up" in t and "robot-1" in t and "2 in all" in t for t in texts)
    w.on_plan("", Plan(4.0, 1, "t00", np.zeros((2, 2))))
    w.on_fleet("", FleetState(20.0, "cleaning", ["robot-0"], [], [], 2, 3, 5))
    start = w.started_wall
    assert start is not None
    # 5 of 10 tasks done in 60 s: 60 s to go
    assert w.snapshot(now=start + 60.0).eta_s == pytest.approx(60.0)


def test_a_view_that_never_saw_the_plan_takes_the_pace_since_it_came() -> None:
    w = _watcher()
    w.on_fleet("", FleetState(20.0, "cleaning", ["robot-0"], [], [], 2, 6, 2))
    assert w.snapshot().eta_s is None  # nothing done while it watched
    assert w._first_state is not None
    came = w._first_state[0]
    w.on_fleet("", FleetState(30.0, "cleaning", ["robot-0"], [], [], 1, 5, 4))
    # 2 tasks in 30 s since it came, 6 to go: 90 s
    assert w.snapshot(now=came + 30.0).eta_s == pytest.approx(90.0)


def test_the_messages_each_process_dropped_show_in_the_header_and_the_line() -> None:
    w = _watcher()
    assert w.dropped() == {"robot-0": (0, 0), "robot-1": (0, 0)}
    assert "dropped" not in plain([header(w.snapshot())]) and "dropped" not in w.line(1.0)
    w.on_fleet("", _recorded(FleetState(20.0, "cleaning", ["robot-0"], [], [], 2, 3, 5, 0, 1, 4)))
    w.on_status(
        KEYS.robot("robot-1", "status"),
        _recorded(
            RobotStatus(13.0, "driving", "t03", 0.5, 4, 10, 5.0, decode_errors=2, implausible=3)
        ),
    )
    w.set_own_dropped("up", 0, 0)
    assert w.dropped() == {
        "coordinator": (1, 4),
        "robot-0": (0, 0),
        "robot-1": (2, 3),
        "up": (0, 0),
    }
    shown = "dropped: coordinator 1 malformed 4 implausible, robot-1 2 malformed 3 implausible"
    assert shown in plain([header(w.snapshot())])
    assert w.line(1.0).endswith(shown)


def test_the_makespan_runs_from_the_first_plan_to_the_job_done() -> None:
    w = _watcher()
    w.on_plan("", Plan(4.0, 1, "t00", np.zeros((2, 2))))
    assert w.makespan() is None
    w.on_fleet("", FleetState(90.0, "done", ["robot-0"], ["robot-0"], [], 0, 0, 5))
    w.on_fleet("", FleetState(95.0, "done", ["robot-0"], ["robot-0"], [], 0, 0, 5))
    assert w.done and w.makespan() == 86.0


def test_keys_from_a_terminal_and_key_patterns_for_the_rates() -> None:
    assert parse_keys(b"\x1b[A\x1b[Bk\x1bOBrq\x1b[Cx") == [UP, DOWN, KILL, DOWN, "respawn", QUIT]
    assert key_class("fleet/default/robot/robot-3/truth") == "robot/*/truth"
    assert key_class("fleet/default/coord/plan/robot-1") == "coord/plan/*"
    assert key_class("fleet/default/coord/bids/robot-1") == "coord/bids/*"
    assert key_class("fleet/default/sim/clock") == "sim/clock"


# ---- a live bus --------------------------------------------------------------------------


def _until(feed: BusFeed, done: Callable[[], bool], timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        feed.pump()
        if done():
            return True
        time.sleep(0.02)
    return False


@pytest.fixture
def router() -> Iterator[str]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = open_router([endpoint])
    try:
        yield endpoint
    finally:
        session.close()


@pytest.mark.timeout(60)
def test_over_a_live_bus_the_marker_follows_the_truth_and_a_dead_agent_shows_lost(
    router: str,
) -> None:
    floor = pack_grid(_room())
    with (
        Bus("dashboard", "view", [router]) as view_bus,
        Bus("coordinator", "c", [router]) as coord,
        Bus("sim", "s", [router]) as sim,
    ):
        from fleet.protocol import Request

        coord.serve(coord.keys.floor_map(), Request, lambda _r: floor)
        agent = Bus("agent", "robot-2", [router])
        w = FleetWatcher()
        feed = BusFeed(view_bus, w, fetch=False)
        try:
            assert _until(feed, lambda: "robot-2" in w.robots), "no liveliness token seen"
            feed.fetch_once()
            assert w.floor is not None, "the floor plan was not fetched"
            key = sim.keys.robot("robot-2", "truth")
            # a stale pose first, then the one the marker must show
            for stamp, x in ((1.0, 0.55), (2.0, 2.55)):
                sim.publish(key, TruthPose(stamp, x, 1.5, 0.0))
            assert _until(feed, lambda: w.robots["robot-2"].pose == (2.55, 1.5, 0.0))
            lines = _map_lines(w)
            assert lines[7][25:27] == "→2"
            agent.close()
            assert _until(feed, lambda: w.snapshot().robots[0].liveness == "lost")
            assert LOST_MARK + "2" in "".join(_map_lines(w))
            assert any(r > 0 for k, r in w.rates.rates() if k == "robot/*/truth")
        finally:
            feed.close()


# ---- the kill key --------------------------------------------------------------------------

SLEEP = "import time; time.sleep(60)"


def _fleet_like(argv: list[str]) -> subprocess.Popen:
    """``python -c <sleep> fleet.cli *argv``: /proc shows fleet.cli followed by argv."""
    cmd = [sys.executable, "-c", SLEEP, "fleet.cli", *argv]
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL)
    deadline = time.monotonic() + 10.0
    while cmdline(proc.pid) != cmd and time.monotonic() < deadline:
        time.sleep(0.01)
    return proc


@pytest.mark.timeout(60)
def test_the_kill_key_sends_the_selected_robots_agent_sigterm(tmp_path: Path) -> None:
    procs = {rid: _fleet_like(["agent", "--id", rid]) for rid in ("robot-0", "robot-1", "robot-2")}
    try:
        records = {
            rid: ProcessRecord(p.pid, ["agent", "--id", rid], time.time())
            for rid, p in procs.items()
        }
        write_table(tmp_path, RunTable("default", "tcp/127.0.0.1:1", 1, "w.yaml", records))
        w = FleetWatcher()
        for rid in procs:
            w.on_alive(rid, True)
        control = ViewControl(w, ProcessActions(tmp_path))
        control.feed(b"\x1b[B\x1b[B\x1b[B\x1b[A")  # robot-0, robot-1, robot-2, back to robot-1
        assert control.selected == "robot-1"
        control.feed(b"k")
        assert procs["robot-1"].wait(timeout=10) == -signal.SIGTERM
        control.feed(b"k")  # again: it has exited, so nothing is signalled and the view says so
        control.close()
        assert procs["robot-0"].poll() is None and procs["robot-2"].poll() is None
        events = [(e.kind, e.text) for e in w.snapshot().events]
        assert (
            "action",
            f"sent SIGTERM to robot-1 (pid {procs['robot-1'].pid}, was running)",
        ) in events
        assert any(
            kind == "error" and "robot-1" in t and "already exited" in t for kind, t in events
        )
    finally:
        for p in procs.values():
            p.kill()
            p.wait()


def test_a_view_that_attaches_late_starts_with_the_jobs_events_and_no_old_news(
    tmp_path: Path,
) -> None:
    from fleet.cli.dashboard import _past_events
    from fleet.coordinator.store import JobStore

    store = JobStore(tmp_path / "coordinator.sqlite")
    store.add_event(1000.0, 5.0, "lost", "robot-1", "t02", "its liveliness token is gone")
    store.add_event(1001.0, 5.1, "awarded", "robot-0", "t02", "")
    store.add_event(1002.0, 5.2, "reassigned", "robot-0", "t02", "0.030 s after the loss")
    store.close()
    w = FleetWatcher()
    _past_events(w, tmp_path / "coordinator.sqlite")
    assert [e.kind for e in w.snapshot().events] == ["lost", "reassigned"]
    # the first status heard sets the count of waypoints given up; only later ones are news
    w.on_status(
        KEYS.robot("robot-0", "status"),
        RobotStatus(6.0, "driving", "t02", 0.1, 1, 9, 1.0, skipped=4),
    )
    assert [e.kind for e in w.snapshot().events] == ["lost", "reassigned"]
    w.on_status(
        KEYS.robot("robot-0", "status"),
        RobotStatus(7.0, "driving", "t02", 0.2, 2, 9, 1.5, skipped=5),
    )
    assert w.snapshot().events[-1].text.endswith("1 unreachable waypoint(s), 5 in all")
    # a new plan: the agent counts from 0 again
    w.on_status(
        KEYS.robot("robot-0", "status"),
        RobotStatus(8.0, "driving", "t03", 0.0, 0, 9, 1.6, skipped=2, plan_id=7),
    )
    assert w.snapshot().events[-1].text.endswith("2 unreachable waypoint(s), 7 in all")
    assert w.snapshot().robots[0].gave_up == 7


@pytest.mark.timeout(60)
def test_without_a_terminal_fleet_dashboard_prints_plain_lines_until_the_fleet_stops(
    router: str, tmp_path: Path
) -> None:
    from fleet.coordinator.store import JobStore

    store = JobStore(tmp_path / "coordinator.sqlite")
    store.add_event(1000.0, 5.0, "lost", "robot-1", "t02", "its liveliness token is gone")
    store.close()
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()  # a `fleet up` that has exited
    table = RunTable("default", router, gone.pid, "w.yaml", {}, [sys.executable, "-c", "pass"])
    write_table(tmp_path, table)
    done = subprocess.run(
        [sys.executable, "-m", "fleet.cli", "dashboard", "--run-dir", str(tmp_path)],
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=50,
    )
    assert done.returncode == 0, done.stderr
    lines = done.stderr.splitlines()
    assert any(ln.startswith("event: ") and "lost" in ln and "robot-1" in ln for ln in lines)
    assert any(" starting sim=" in ln for ln in lines), lines
    assert "fleet up has exited: the fleet is stopped" in lines
    assert "\x1b[" not in done.stderr + done.stdout  # no screen drawn


def test_the_view_drops_what_is_stamped_past_the_sim_clock() -> None:
    """A status or a clock stamped 1e9 s would stand as the newest for good: the robot's real
    statuses and the real clock after it would never show. With its watch on the sim clock the
    view drops them, and counts them through the watch."""
    dropped: list[tuple[str, str]] = []
    watch = StampWatch(0.5, lambda key, who, why, n=1: dropped.append((key, who)), KEYS.clock())
    for t in (9.9, 10.0, 10.1):
        watch.hear_clock(KEYS.clock(), Clock(t, 1.0))
    w = FleetWatcher(watch=watch)
    w.on_alive("robot-1", True)
    key = KEYS.robot("robot-1", "status")
    for t in (1e9, 10.2):
        w.on_status(key, _recorded(RobotStatus(t, "driving", f"t{t:.0f}", 0.4, 3, 10, 4.2)))
    w.on_clock(KEYS.clock(), Clock(1e9, 1.0))
    w.on_clock(KEYS.clock(), Clock(10.1, 1.0))
    status = w.robots["robot-1"].status
    assert status is not None and status.stamp == 10.2
    assert w.clock == 10.1
    assert dropped == [(key, "robot-1")]


def test_the_view_drops_what_robots_not_in_the_job_send() -> None:
    """A status, intent or heartbeat from a robot whose liveliness token the view never heard
    would show it as a robot of the fleet (and put it in report.json): with its watch the view
    drops each, counted with the sender named, and takes those of robots in the job, also
    once a robot's token went."""
    dropped: list[tuple[str, str]] = []
    watch = StampWatch(0.5, lambda key, who, why, n=1: dropped.append((key, who)), KEYS.clock())
    watch.hear_clock(KEYS.clock(), Clock(0.5, 1.0))
    w = FleetWatcher(watch=watch)
    w.on_alive("robot-0", True)
    w.on_alive("robot-0", False)
    points = np.array([[1.0, 0.5, 0.5], [2.0, 0.6, 0.5]])
    for rid in ("ghost", "robot-0"):
        w.on_status(KEYS.robot(rid, "status"), RobotStatus(1.0, "driving", "t00", 0.5, 1, 2, 0.0))
        w.on_intent(KEYS.robot(rid, "intent"), Intent(1.0, points, 1, 1))
        w.on_heartbeat(KEYS.robot(rid, "heartbeat"), Heartbeat(1.0, 1, True))
    assert list(w.robots) == ["robot-0"]
    robot = w.robots["robot-0"]
    assert robot.status is not None and robot.intent is not None
    # counted once the ghost's token has not come within the grace
    assert dropped == []
    watch.strangers.grace_s = 0.0
    watch.strangers.flush()
    assert dropped == [
        (KEYS.robot("ghost", topic), "ghost") for topic in ("status", "intent", "heartbeat")
    ]


def test_a_view_started_late_believes_no_stamp_before_its_clock_has_synced() -> None:
    """A view started while a rogue sends knows no sim time until its clock has synced: a
    status stamped 1e9 s taken then would stand as the robot's newest and hide every real one
    after it. Until the clock syncs, stamped messages are dropped, uncounted."""
    dropped: list[tuple[str, str]] = []
    watch = StampWatch(0.5, lambda key, who, why, n=1: dropped.append((key, who)), KEYS.clock())
    w = FleetWatcher(watch=watch)
    w.on_alive("robot-1", True)
    key = KEYS.robot("robot-1", "status")
    w.on_status(key, _recorded(RobotStatus(1e9, "driving", "t00", 0.4, 3, 10, 4.2)))
    for t in (10.0, 10.05, 10.1):  # the clock of a fleet that has run for 10 s, confirmed
        watch.hear_clock(KEYS.clock(), Clock(t, 1.0))
    w.on_status(key, _recorded(RobotStatus(10.2, "driving", "t00", 0.4, 3, 10, 4.2)))
    status = w.robots["robot-1"].status
    assert status is not None and status.stamp == 10.2
    assert dropped == []


def test_the_robot_table_shows_each_robots_charge() -> None:
    from fleet.dashboard.view import battery_cell

    assert battery_cell(None, False) == "—"
    assert battery_cell(0.456, False) == "46 %"
    assert battery_cell(0.456, True) == "+46 %"


def test_the_rate_meter_holds_one_window_of_counts_when_nobody_reads_it():
    """`fleet up --headless` counts every message and never reads the rates: what the meter
    holds must stay one window's worth, not the whole run's."""
    meter = RateMeter(window_s=5.0)
    for k in range(20_000):
        meter.count("robot/robot-0/odom", 1, now=0.01 * k)
    held = sum(len(seen) for seen in meter._seen.values())
    assert held <= 5.0 / 0.01 + 1
    assert meter.rates(now=0.01 * 19_999) == [("odom", pytest.approx(100.0, rel=0.01))]
