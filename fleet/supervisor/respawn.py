"""`fleet respawn NAME` as `fleet up` answers it: the process started again with the arguments
it had, by the main thread of `fleet up`, never by the Zenoh callback thread that heard the
request."""

from __future__ import annotations

import queue
import sys
from collections.abc import Callable
from concurrent import futures
from typing import Any

from fleet.protocol import OpsReply, OpsRequest
from fleet.supervisor.launcher import Launcher

# an operator's respawn waits this long for the main loop, which looks every REDRAW_S
RESPAWN_WAIT_S = 5.0
# The fleet cannot go on without these; every other process can be started again by
# `fleet respawn NAME`.
FATAL_PROCESSES = ("router", "sim")


class MainThreadCalls:
    """Calls asked for on other threads, made by the main thread between two looks at the
    fleet. A process started from a Zenoh callback thread would get its parent-death signal
    when that thread ends (Linux ties ``PR_SET_PDEATHSIG`` to the thread that forked)."""

    def __init__(self) -> None:
        self._pending: queue.Queue[tuple[Callable[[], Any], futures.Future]] = queue.Queue()

    def call(self, fn: Callable[[], Any], timeout: float) -> Any:
        """``fn()`` made by the main thread; raises TimeoutError if it does not get to it."""
        done: futures.Future = futures.Future()
        self._pending.put((fn, done))
        return done.result(timeout)

    def run_pending(self) -> None:
        while True:
            try:
                fn, done = self._pending.get_nowait()
            except queue.Empty:
                return
            try:
                done.set_result(fn())
            except Exception as e:
                done.set_exception(e)


def respawner(launcher: Launcher, calls: MainThreadCalls) -> Callable[[OpsRequest], OpsReply]:
    """The answer to `fleet respawn NAME`: start NAME again with the arguments it had (plus
    ``--respawn`` for an agent, which then reloads its map and pose from its --state-dir; the
    coordinator resumes from its --state file)."""

    def answer(req: OpsRequest) -> OpsReply:
        try:
            return calls.call(lambda: respawn(req), RESPAWN_WAIT_S)
        except futures.TimeoutError:
            return OpsReply(False, "fleet up did not get to it: it is stopping")

    def respawn(req: OpsRequest) -> OpsReply:
        if req.verb != "respawn":
            return OpsReply(False, f"unknown verb {req.verb!r}; this key answers respawn")
        if req.name in FATAL_PROCESSES:
            return OpsReply(False, f"{req.name} cannot be respawned: the fleet stops without it")
        record = launcher.records.get(req.name)
        if record is None:
            names = ", ".join(n for n in launcher.records if n not in FATAL_PROCESSES)
            return OpsReply(False, f"no process {req.name!r} in this fleet; there are: {names}")
        args = list(record.argv)
        if args[:1] == ["agent"] and "--respawn" not in args:
            args.append("--respawn")
        try:
            proc = launcher.restart(req.name, args)
        except (ValueError, RuntimeError, OSError) as e:
            return OpsReply(False, str(e))
        print(f"respawned {req.name} for {req.sender} (pid {proc.pid})", file=sys.stderr)
        return OpsReply(True, "")

    return answer
