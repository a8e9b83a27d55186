"""Operator actions on the processes of a running fleet, shared by the operator verbs
(`fleet kill`, `fleet respawn`, `fleet down`, `fleet status`) and the live views' kill and
respawn keys (`fleet up`, `fleet dashboard`).

Each reads the run dir's process table (``processes.json``, written by `fleet up`, see
:mod:`fleet.rundir`) and checks a pid against /proc before acting on it.
"""

from __future__ import annotations

import os
import signal
import threading
from enum import Enum
from pathlib import Path
from typing import Any

from fleet.rundir import RunTable, is_alive, process_state, read_table

COORDINATOR = "coordinator"
# the coordinator's job state in a run dir
STATE_FILE = "coordinator.sqlite"
RESPAWN_TIMEOUT_S = 10.0


class Sig(str, Enum):
    KILL = "KILL"
    TERM = "TERM"
    STOP = "STOP"
    CONT = "CONT"


class OpsError(Exception):
    """An operator verb that cannot be done; the message says why and what to do instead."""


def _target(run_dir: Path, table: RunTable, name: str) -> tuple[int, list[str]]:
    """The pid and argv of robot or coordinator ``name``; OpsError for any other name."""
    record = table.processes.get(name)
    if record is None or (name != COORDINATOR and name not in table.robots()):
        robots = ", ".join(table.robots()) or "none"
        raise OpsError(f"no robot {name!r} in {run_dir}; robots: {robots}; or {COORDINATOR!r}")
    return record.pid, record.argv


def _up_state(table: RunTable) -> str:
    return process_state(table.up_pid, table.up_cmdline)


def send_signal(run_dir: Path, table: RunTable, name: str, sig: Sig) -> str:
    """`fleet kill NAME --signal SIG` (and the dashboard's kill key): signal robot or
    coordinator ``name`` of the run in ``run_dir`` after checking its pid against /proc.
    Returns what was done; raises OpsError naming the reason when it cannot be done."""
    pid, argv = _target(run_dir, table, name)
    state = process_state(pid, argv)
    if not is_alive(state):
        raise OpsError(
            f"{name} (pid {pid}) has already exited; `fleet respawn {name}` starts it again"
        )
    signum = signal.Signals[f"SIG{sig.value}"]
    try:
        os.kill(pid, signum)
    except ProcessLookupError:
        raise OpsError(f"{name} (pid {pid}) has already exited") from None
    except PermissionError:
        raise OpsError(
            f"not allowed to signal {name} (pid {pid}): it belongs to another user"
        ) from None
    return f"sent SIG{sig.value} to {name} (pid {pid}, was {state})"


def ask_respawn(run_dir: Path, table: RunTable, name: str, timeout: float, sender: str) -> str:
    """`fleet respawn NAME` (and the dashboard's respawn key): ask the run's `fleet up` to
    start ``name`` again. Returns what was done; raises OpsError naming the reason when it
    cannot be done (still alive, fleet up gone, no answer, refused)."""
    from fleet.protocol import Keys, OpsReply, OpsRequest

    pid, argv = _target(run_dir, table, name)
    if is_alive(process_state(pid, argv)):
        raise OpsError(f"{name} is alive (pid {pid}); kill it first: `fleet kill {name}`")
    if not is_alive(_up_state(table)):
        raise OpsError(f"is fleet up still running? its pid {table.up_pid} is gone")
    key = Keys(table.fleet).ops("respawn")
    request = OpsRequest(sender=sender, verb="respawn", name=name)
    reply = _ask(table, key, request, OpsReply, timeout)
    if not reply.ok:
        raise OpsError(f"fleet up refused: {reply.error}")
    record = read_table(run_dir).processes[name]
    return (
        f"respawned {name}: pid {record.pid}, restart {record.restarts}; log {run_dir / record.log}"
    )


def ask_dock(table: RunTable, name: str, timeout: float, sender: str, dock: int = -1) -> str:
    """`fleet dock ROBOT`: ask the run's coordinator to send ``name`` home now (its work goes
    back to the market; it charges to ``robot.battery.recharge_to`` and bids again), to dock
    number ``dock`` of the world's (−1: the one the coordinator picks). Returns what was done;
    raises OpsError naming the reason when it cannot be done."""
    from fleet.protocol import Keys, OpsReply, OpsRequest

    key = Keys(table.fleet).ops("dock")
    request = OpsRequest(sender=sender, verb="dock", name=name, dock=dock)
    try:
        reply = _ask(table, key, request, OpsReply, timeout)
    except OpsError as e:
        raise OpsError(
            f"{e} (only a coordinator with robot.battery on sends robots home)"
        ) from None
    if not reply.ok:
        raise OpsError(f"the coordinator refused: {reply.error}")
    return f"{name} is on its way to {'a dock' if dock < 0 else f'dock {dock}'}"


class ProcessActions:
    """The dashboard's kill and respawn keys: `fleet kill NAME` (SIGTERM) and `fleet respawn
    NAME` on the run in ``run_dir``, read afresh each time; each returns what was done or
    raises OpsError (or RunDirError) saying why not."""

    def __init__(self, run_dir: Path, respawn_timeout: float = RESPAWN_TIMEOUT_S) -> None:
        self.run_dir = run_dir
        self.respawn_timeout = respawn_timeout

    def kill(self, name: str) -> str:
        return send_signal(self.run_dir, read_table(self.run_dir), name, Sig.TERM)

    def respawn(self, name: str) -> str:
        table = read_table(self.run_dir)
        return ask_respawn(self.run_dir, table, name, self.respawn_timeout, sender="dashboard")


def _ask(table: RunTable, key: str, request: Any, reply_cls: type, timeout: float) -> Any:
    from fleet.bus import Bus

    try:
        bus = Bus(
            "cli", f"ops-{os.getpid()}-{threading.get_ident()}", [table.endpoint], fleet=table.fleet
        )
    except Exception as e:  # zenoh raises ZError when the router cannot be reached
        raise OpsError(f"cannot reach the fleet's router at {table.endpoint}: {e}") from None
    try:
        return bus.request(key, request, reply_cls, timeout=timeout)
    except TimeoutError:
        raise OpsError(
            f"fleet up (pid {table.up_pid}) did not answer on {key} within {timeout} s; "
            "is fleet up still running?"
        ) from None
    except RuntimeError as e:
        raise OpsError(f"fleet up could not answer: {e}") from None
    finally:
        bus.close()
