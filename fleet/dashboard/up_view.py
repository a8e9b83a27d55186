"""What `fleet up` and `fleet explore` show while their fleet runs: on a terminal (and without
--headless) the live view of `fleet dashboard`, until q closes it; then, as without a terminal,
plain lines: each event, and the fleet's status line every PLAIN_LINE_S. The watch that drives
it is `fleet.supervisor.fleet_processes.FleetProcesses.watch` (this is its ``FleetView``)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fleet.dashboard.model import BusFeed, FleetWatcher
from fleet.protocol import DEFAULT_FLEET

if TYPE_CHECKING:
    from fleet.bus import Bus
    from fleet.dashboard.term import TerminalView, ViewControl
    from fleet.params import FleetConfig
    from fleet.plausible import StampWatch
    from fleet.rundir import Dropped

# a status line this often (wall seconds) without the live view
PLAIN_LINE_S = 5.0


class UpView:
    """The fleet on ``bus`` as a :class:`FleetWatcher` sees it (its stamps judged by
    ``stamps``), shown live or as lines; the k and r keys act on the processes of ``run_dir``.
    With ``headless`` the floor plan and the cleaned area are not fetched (nothing draws them)."""

    def __init__(
        self, bus: Bus, cfg: FleetConfig, stamps: StampWatch, run_dir: Path, headless: bool
    ) -> None:
        self.watcher = FleetWatcher(DEFAULT_FLEET, cfg.coordinator.heartbeat_timeout_s, stamps)
        self.feed = BusFeed(bus, self.watcher, fetch=not headless)
        self.run_dir = run_dir
        self.headless = headless
        self.console: Any = None
        self.control: ViewControl | None = None
        self.live: TerminalView | None = None
        self._last_line = -1e9

    def start(self) -> None:
        from rich.console import Console

        from fleet.dashboard.term import TerminalView, ViewControl
        from fleet.supervisor.ops import ProcessActions

        self.console = Console(stderr=True)
        self.control = ViewControl(self.watcher, ProcessActions(self.run_dir))
        if not self.headless and self.console.is_terminal:
            self.live = TerminalView(self.watcher, self.control, self.console)
            self.live.start()

    def pump(self) -> None:
        self.feed.pump()

    def show(self, wall_s: float) -> None:
        assert self.control is not None, "start the view first"
        if self.live is not None and self.control.quit.is_set():
            self.end_live()
            self.watcher.take_events()  # the view has shown them
            self.console.print("the view is closed; the fleet runs on (Ctrl-C stops it)")
        if self.live is not None:
            self.live.draw()
            return
        for line in self.watcher.take_events():
            print(f"event: {line}", file=sys.stderr, flush=True)
        if wall_s - self._last_line >= PLAIN_LINE_S:
            print(self.watcher.line(wall_s), file=sys.stderr, flush=True)
            self._last_line = wall_s

    def end_live(self) -> None:
        """Close the live view (if open): from here on, plain lines."""
        if self.live is not None:
            self.live.stop()
            self.live = None

    def _say(self, text: str, kind: str) -> None:
        if self.live is not None:
            self.watcher.note(kind, text)
        else:
            self.console.print(f"[{'red' if kind == 'error' else 'yellow'}]{text}")

    def fatal(self, text: str) -> None:
        self.end_live()
        self._say(text, "error")

    def lost(self, text: str) -> None:
        self._say(text, "lost")

    def restarts(self, counts: dict[str, int]) -> None:
        self.watcher.set_restarts(counts)

    def dropped(self) -> Dropped:
        return self.watcher.dropped()

    def finished(self) -> str | None:
        return self.watcher.phase if self.watcher.done else None

    def close(self, wall_s: float) -> None:
        """Close the live view and the key actions; the fleet's last status line."""
        self.end_live()
        if self.control is not None:
            self.control.close()
        print(self.watcher.line(wall_s), file=sys.stderr, flush=True)

    def detach(self) -> None:
        """Take in what is left on the bus, then stop listening (the watcher keeps what it
        saw, for the report)."""
        self.feed.pump()
        self.feed.close()

    def job_sim_s(self) -> float:
        """The sim time the job finished at, or the sim clock's last if it did not."""
        with self.watcher.lock:
            w = self.watcher
            return w.finished_at if w.finished_at is not None else w.clock
