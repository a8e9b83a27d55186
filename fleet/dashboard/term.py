"""The dashboard in a terminal: keys, the robot selection, the operator's actions, and the
redraw loop around :func:`fleet.dashboard.view.screen`.

Drawn on the terminal's alternate screen as plain ANSI text (so it works over SSH and in
tmux, and the shell's screen comes back on exit); keys are read from stdin in cbreak mode by a
thread of their own, so Ctrl-C still interrupts. Keys: ↑/↓ select a robot, ``k`` sends its
agent SIGTERM (as ``fleet kill NAME`` does), ``r`` respawns it (as ``fleet respawn NAME``),
``q`` closes the view and leaves the fleet running. Actions run on a worker thread, so the
view never waits for them; their outcome shows among the events.
"""

from __future__ import annotations

import contextlib
import os
import select
import sys
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Protocol

from fleet.dashboard.model import FleetWatcher

UP, DOWN, KILL, RESPAWN, QUIT = "up", "down", "kill", "respawn", "quit"
_SEQUENCES = {
    b"\x1b[A": UP,
    b"\x1bOA": UP,
    b"\x1b[B": DOWN,
    b"\x1bOB": DOWN,
    b"k": KILL,
    b"r": RESPAWN,
    b"q": QUIT,
}
KEY_POLL_S = 0.1
KEYS_HELP = "↑/↓ select a robot · k kill it (SIGTERM) · r respawn it · q close the view"
NO_TABLE_HELP = "↑/↓ select · q close the view · (no run dir, so k and r are off)"


def parse_keys(data: bytes) -> list[str]:
    """The keys in a chunk read from a terminal; bytes that are no key of ours are skipped
    (an unknown escape sequence as a whole)."""
    keys = []
    i = 0
    while i < len(data):
        for seq, key in _SEQUENCES.items():
            if data.startswith(seq, i):
                keys.append(key)
                i += len(seq)
                break
        else:
            if data[i : i + 1] == b"\x1b" and data[i + 1 : i + 2] in (b"[", b"O"):
                i += 3
            else:
                i += 1
    return keys


class Actions(Protocol):
    """Kill or respawn a robot's process; each returns what was done, or raises an exception
    whose message says why it could not be done (see ``fleet.supervisor.ops.ProcessActions``)."""

    def kill(self, name: str) -> str: ...

    def respawn(self, name: str) -> str: ...


class ViewControl:
    """What the keys do: the selected robot, and kill or respawn of it on a worker thread.
    ``actions`` None (no run dir known) turns k and r off."""

    def __init__(self, watcher: FleetWatcher, actions: Actions | None) -> None:
        self.watcher = watcher
        self.actions = actions
        self.selected: str | None = None
        self.quit = threading.Event()
        self._lock = threading.Lock()
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="dashboard-action")

    @property
    def help(self) -> str:
        return KEYS_HELP if self.actions is not None else NO_TABLE_HELP

    def feed(self, data: bytes) -> None:
        """Act on the keys in ``data``, as read from the terminal."""
        for key in parse_keys(data):
            self.press(key)

    def press(self, key: str) -> None:
        if key == QUIT:
            self.quit.set()
        elif key in (UP, DOWN):
            self._move(-1 if key == UP else 1)
        elif key in (KILL, RESPAWN):
            self._act(key)

    def _move(self, step: int) -> None:
        with self.watcher.lock:
            robots = sorted(self.watcher.robots)
        if not robots:
            return
        with self._lock:
            if self.selected not in robots:
                self.selected = robots[0] if step > 0 else robots[-1]
            else:
                self.selected = robots[(robots.index(self.selected) + step) % len(robots)]

    def _act(self, key: str) -> None:
        with self._lock:
            name = self.selected
        if self.actions is None:
            self.watcher.note("error", "no run dir: k and r need the run's processes.json")
            return
        if name is None:
            self.watcher.note("error", "select a robot first with ↑/↓")
            return
        do = self.actions.kill if key == KILL else self.actions.respawn
        self.watcher.note("action", f"{'killing' if key == KILL else 'respawning'} {name} …")
        self._worker.submit(self._run, do, name)

    def _run(self, do: Callable[[str], str], name: str) -> None:
        try:
            self.watcher.note("action", do(name))
        except Exception as e:
            self.watcher.note("error", str(e) or f"{name}: {type(e).__name__}")

    def close(self) -> None:
        """Wait for an action under way, then stop the worker."""
        self._worker.shutdown(wait=True)


class TerminalView:
    """The live screen: :meth:`start`, then :meth:`draw` at each tick, then :meth:`stop`.
    Keys are read while it runs if stdin is a terminal."""

    def __init__(self, watcher: FleetWatcher, control: ViewControl, console: Any) -> None:
        self.watcher = watcher
        self.control = control
        self.console = console
        self.note = ""
        self._live = False
        self._writer: Any = None
        self._keys: threading.Thread | None = None
        self._stop = threading.Event()
        self._tty_saved: Any = None

    def start(self) -> None:
        from fleet.dashboard.view import AnsiWriter

        self._writer = AnsiWriter(self.console.color_system)
        self.console.set_alt_screen(True)
        self.console.show_cursor(False)
        self._live = True
        if sys.stdin is not None and sys.stdin.isatty():
            import termios
            import tty

            fd = sys.stdin.fileno()
            self._tty_saved = termios.tcgetattr(fd)
            tty.setcbreak(fd)
            self._keys = threading.Thread(target=self._read_keys, args=(fd,), daemon=True)
            self._keys.start()

    def _read_keys(self, fd: int) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select([fd], [], [], KEY_POLL_S)
            if not ready:
                continue
            try:
                data = os.read(fd, 64)
            except OSError:
                return
            if not data:
                return
            self.control.feed(data)

    def draw(self) -> None:
        from dataclasses import replace

        from fleet.dashboard.view import screen

        width, height = self.console.size
        snap = self.watcher.snapshot()
        if self.note:
            snap = replace(snap, note=self.note)
        lines = screen(snap, width, height, self.control.selected, self.control.help)
        self.console.file.write(self._writer.frame(lines))
        self.console.file.flush()

    def stop(self) -> None:
        self._stop.set()
        if self._keys is not None:
            self._keys.join(timeout=2 * KEY_POLL_S + 1.0)
        if self._tty_saved is not None:
            import termios

            with contextlib.suppress(termios.error):
                termios.tcsetattr(sys.stdin.fileno(), termios.TCSADRAIN, self._tty_saved)
            self._tty_saved = None
        if self._live:
            self.console.show_cursor(True)
            self.console.set_alt_screen(False)
            self._live = False
