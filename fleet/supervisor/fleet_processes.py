"""The processes of a `fleet up` (or `fleet explore`) on this machine: started in order into
its run dir (router, simulator, coordinator, one agent per robot), watched until the run ends,
respawned on request (`fleet respawn NAME`), asked for the simulator's report, and stopped.

What the watch shows (the live view of `fleet dashboard`, or plain lines) and what the job's
phase is are the face's (:class:`FleetView`; `fleet.dashboard.up_view.UpView`): this module
judges the processes only."""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, TypeVar

from fleet.protocol import DEFAULT_FLEET, OpsRequest, Request
from fleet.rundir import Dropped, ProcessRecord, RunTable, cmdline, write_dropped, write_table
from fleet.supervisor.launcher import Launcher, WorkWatch, free_port, wait_for_port
from fleet.supervisor.respawn import FATAL_PROCESSES, MainThreadCalls, respawner

if TYPE_CHECKING:
    from fleet.bus import Bus
    from fleet.protocol import Message

M = TypeVar("M", bound="Message")

# the coordinator on a stored map (`--map`) stopped the run: the robots' scans do not match it
WRONG_MAP_EXIT = 5
# the run's status (report.json) when the coordinator stopped it so (exit status WRONG_MAP_EXIT)
WRONG_MAP = "wrong-map"
# The simulator is asked for the report this long at a time (wall seconds), again while it
# works (it lives and uses CPU: a starved machine slows it down), for at most REPORT_GIVE_UP_S;
# a query nothing serves yet (a simulator still starting) returns at once, and is asked again
# after REPORT_POLL_S.
REPORT_WAIT_S = 30.0
REPORT_POLL_S = 1.0
REPORT_GIVE_UP_S = 300.0
# the router's port is waited for this long at a time, again while it works, at most ..._GIVE_UP_S
ROUTER_WAIT_S = 15.0
ROUTER_GIVE_UP_S = 120.0
# the fleet is looked at (and the live view redrawn) this often, in wall seconds
REDRAW_S = 0.2


@dataclass(frozen=True)
class FleetSpec:
    """What to start: the simulator on ``world_path`` at ``speed`` with noise ``seed``, the
    coordinator with the extra arguments ``coordinator``, one agent per start pose (the last
    ``unknown_start`` not told theirs), every process on the parameters ``config`` (None: the
    built-in ones)."""

    world_path: str
    starts: tuple[tuple[float, float, float], ...]
    speed: float
    seed: int
    config: Path | None
    coordinator: tuple[str, ...] = ()
    unknown_start: int = 0


class StartError(RuntimeError):
    """The fleet could not be started (its router did not come up)."""


class FleetView(Protocol):
    """What the watch shows the run on, and how it learns the job's end."""

    def start(self) -> None: ...

    def pump(self) -> None:
        """Take in what the bus brought since the last look."""

    def show(self, wall_s: float) -> None:
        """Draw the live view, or print the news as plain lines."""

    def fatal(self, text: str) -> None:
        """The run ends for ``text``: the live view closes and ``text`` shows as an error."""

    def lost(self, text: str) -> None:
        """A process is gone and the run goes on."""

    def restarts(self, counts: dict[str, int]) -> None: ...

    def dropped(self) -> Dropped:
        """The messages each process dropped, as heard."""

    def finished(self) -> str | None:
        """The job's phase once it has finished, else None."""

    def close(self, wall_s: float) -> None: ...


class FleetProcesses:
    """The processes of one run in ``run_dir``, its process table kept there as they start;
    :meth:`start`, :meth:`watch`, then :meth:`close`. ``stop``, set (by
    :func:`stop_on_signals`), ends the watch; ``t0`` is when the run began (time.monotonic)."""

    def __init__(self, run_dir: Path, spec: FleetSpec) -> None:
        self.run_dir = run_dir
        self.spec = spec
        self.port = free_port()
        self.endpoint = f"tcp/127.0.0.1:{self.port}"
        self._cmdline = cmdline(os.getpid()) or []
        self.launcher = Launcher(run_dir, on_change=self._save_table)
        self.calls = MainThreadCalls()
        self.stop = threading.Event()
        self.bus: Bus | None = None
        self.sim: WorkWatch | None = None
        self.t0 = time.monotonic()

    def _save_table(self, records: dict[str, ProcessRecord]) -> None:
        table = RunTable(
            DEFAULT_FLEET, self.endpoint, os.getpid(), self.spec.world_path, records, self._cmdline
        )
        write_table(self.run_dir, table)

    def start(self) -> Bus:
        """Start the processes (:meth:`_start_processes`), open the bus to watch them on, and
        answer `fleet respawn` there; the bus."""
        from fleet.bus import Bus

        self.sim = self._start_processes()
        self.bus = Bus("dashboard", "up", [self.endpoint])
        self.bus.serve(
            self.bus.keys.ops("respawn"), OpsRequest, respawner(self.launcher, self.calls)
        )
        return self.bus

    def _start_processes(self) -> WorkWatch:
        """Start the router (and wait for its port), the simulator, the coordinator (its state
        in the run dir) and one agent per start pose, the last ``unknown_start`` not told
        theirs (the coordinator waits only for the others: those are ready once placed); the
        simulator's watch. StartError if the router does not come up."""
        spec, run_dir = self.spec, self.run_dir
        common = ["--connect", self.endpoint] + (
            ["--config", str(spec.config)] if spec.config else []
        )
        router = WorkWatch(
            self.launcher.start("router", ["router", "--listen", f"tcp/127.0.0.1:{self.port}"])
        )
        waited = 0.0
        while not wait_for_port("127.0.0.1", self.port, ROUTER_WAIT_S):
            waited += ROUTER_WAIT_S
            if not router.working() or waited >= ROUTER_GIVE_UP_S:
                raise StartError(f"the Zenoh router did not start; see {run_dir / 'router.log'}")
        world = ["--world", spec.world_path]
        sim_args = ["sim", *world, "--speed", str(spec.speed), "--seed", str(spec.seed)]
        sim = WorkWatch(self.launcher.start("sim", [*sim_args, *common]))
        state = ["--state", str(run_dir / "coordinator.sqlite"), *spec.coordinator]
        robots = ["--robots", str(len(spec.starts) - spec.unknown_start)]
        self.launcher.start("coordinator", ["coordinator", *robots, *world, *common, *state])
        for i, (x, y, th) in enumerate(spec.starts):
            rid = f"robot-{i}"
            state = ["--state-dir", str(run_dir / rid)]
            if i >= len(spec.starts) - spec.unknown_start:
                state.append("--unknown-start")
            start = ["--start", f"{x},{y},{th}"]
            self.launcher.start(rid, ["agent", "--id", rid, *start, *common, *state])
        return sim

    def watch(self, view: FleetView, until_done: bool, timeout: float | None) -> str:
        """Show progress on ``view`` until the job is done (with ``until_done``), ``timeout``
        wall seconds have passed, :attr:`stop` is set, the router or the simulator is dead, or
        the coordinator failed with an error; why it stopped: the job's phase, ``timeout``,
        ``stopped``, ``error`` or WRONG_MAP. Another process that dies (a killed coordinator,
        any agent) is told once, and the run goes on."""
        reported: dict[str, int] = {}
        dropped: Dropped = {}
        try:
            view.start()
            while not self.stop.wait(REDRAW_S):
                self.calls.run_pending()
                view.pump()
                wall = time.monotonic() - self.t0
                view.show(wall)
                dead = self.launcher.dead()
                fatal = _fatal(dead)
                if fatal is not None:
                    return self._ended_by(*fatal, view)
                self._tell_lost(dead, reported, view)
                view.restarts({n: r.restarts for n, r in self.launcher.records.items()})
                if view.dropped() != dropped:
                    dropped = view.dropped()
                    write_dropped(self.run_dir, dropped)
                phase = view.finished()
                if until_done and phase is not None:
                    return phase
                if timeout is not None and wall > timeout:
                    return "timeout"
            phase = view.finished()
            return phase if phase is not None else "stopped"
        finally:
            view.close(time.monotonic() - self.t0)

    def _ended_by(self, name: str, code: int, view: FleetView) -> str:
        log = self.run_dir / (name + ".log")
        if name == "coordinator" and code == WRONG_MAP_EXIT:
            view.fatal(f"the coordinator refused the stored map; see {log}")
            return WRONG_MAP
        view.fatal(f"{name} exited with code {code}; see {log}")
        return "error"

    def _tell_lost(self, dead: dict[str, int], reported: dict[str, int], view: FleetView) -> None:
        """Tell each process found dead once per start (``reported``: the restarts told)."""
        for name, code in dead.items():
            restarts = self.launcher.records[name].restarts
            if reported.get(name) != restarts:
                reported[name] = restarts
                view.lost(f"{name} exited with code {code}; `fleet respawn {name}` starts it again")

    def ask_sim(self, key: str, cls: type[M]) -> M:
        """The simulator's answer on ``key`` (:func:`ask_sim`)."""
        assert self.bus is not None and self.sim is not None, "start the fleet first"
        return ask_sim(self.bus, key, cls, self.sim)

    def close(self) -> None:
        """Close the bus, then stop every process (newest first)."""
        if self.bus is not None:
            self.bus.close()
        self.launcher.stop_all()


def _fatal(dead: dict[str, int]) -> tuple[str, int] | None:
    """The first dead process the fleet cannot go on without, with its exit code: the router,
    the simulator, or a coordinator that failed by itself (not killed by a signal), which fails
    again if respawned."""
    for name, code in dead.items():
        if name in FATAL_PROCESSES or (name == "coordinator" and code > 0):
            return name, code
    return None


def ask_sim(bus: Bus, key: str, cls: type[M], sim: WorkWatch) -> M:
    """The simulator's answer on ``key`` for the report. A starved machine can keep a live
    simulator from answering (or from serving at all yet: a query nothing serves returns at
    once) for long, so it is asked again, every REPORT_POLL_S at most, while it works (judged
    over each REPORT_WAIT_S), for at most REPORT_GIVE_UP_S; TimeoutError once it has exited,
    has stopped or hung, or then."""
    start = looked = time.monotonic()
    while True:
        asked = time.monotonic()
        try:
            return bus.request(key, Request("up"), cls, timeout=REPORT_WAIT_S)
        except TimeoutError:
            pass
        time.sleep(max(0.0, REPORT_POLL_S - (time.monotonic() - asked)))
        now = time.monotonic()
        why = ""
        if not sim.alive():
            why = "has exited"
        elif now - looked >= REPORT_WAIT_S:
            looked = now
            if not sim.working():
                why = "is not working (stopped or hung)"
            elif now - start >= REPORT_GIVE_UP_S:
                why = "still works but does not answer"
            else:
                print(
                    f"the simulator has not answered in {now - start:.0f} s; it works (a busy "
                    "machine): asking again",
                    file=sys.stderr,
                    flush=True,
                )
        if why:
            raise TimeoutError(f"{key}: no answer in {now - start:.0f} s; the simulator {why}")


def stop_on_signals(stop: threading.Event) -> None:
    """Set ``stop`` on SIGINT, SIGTERM or SIGHUP. On SIGHUP the terminal is gone (a closed
    window or SSH session): what would be printed has nowhere to go, and writing to it would
    fail before the report is written, so stdout and stderr go to /dev/null."""

    def on_signal(signum: int, _frame: object) -> None:
        if signum == signal.SIGHUP:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            os.dup2(devnull, sys.stderr.fileno())
        stop.set()

    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, on_signal)
