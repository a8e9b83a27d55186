"""A real `fleet up` for integration tests: :class:`fleet.supervisor.runner.RunningFleet` with
test-failing waits and verbs, and everything a failed run needs to be understood from CI's
output alone."""

from __future__ import annotations

import subprocess
from pathlib import Path

import yaml

from fleet.params import default_config_path
from fleet.supervisor.runner import RunningFleet

WORLDS = Path(__file__).resolve().parents[1] / "configs" / "worlds"


class FleetRun(RunningFleet):
    """``fleet up`` on ``configs/worlds/<world>.yaml`` (or a world file's path) with three
    robots, with no wall ``--timeout``: :meth:`finish` waits ``timeout_s`` wall seconds, and on
    while the sim clock moves (:meth:`RunningFleet.guard`), so a run slowed down by a busy
    machine is not cut."""

    def __init__(
        self,
        run_dir: Path,
        robots: int = 3,
        world: str = "small",
        timeout_s: float = 300.0,
        speed: float = 0.0,
        options: tuple[str, ...] = (),
    ) -> None:
        path = world if world.endswith(".yaml") else str(WORLDS / f"{world}.yaml")
        super().__init__(run_dir, path, robots, speed=speed, options=options)
        self.timeout_s = timeout_s

    def wait_for(self, pred, timeout: float = 120.0, what: str = "") -> None:
        if not self.wait(pred, timeout, poll=0.2):
            raise AssertionError(f"not seen: {what}\n{self.explained()}")

    def verb(self, *args: str) -> subprocess.CompletedProcess:
        """``fleet <args> --run-dir <this run>``; fails the test if it does not exit 0."""
        done = super().verb(*args)
        assert done.returncode == 0, f"fleet {' '.join(args)}: {done.stdout}{done.stderr}"
        return done

    def finish(self, timeout: float | None = None) -> dict:
        report = super().finish(self.timeout_s if timeout is None else timeout)
        assert report is not None, self.explained()
        return report

    def explained(self) -> str:
        """The report, the events and every warning the processes logged."""
        report = self.dir / "report.json"
        warnings = [
            line
            for log in sorted(self.dir.glob("*.log"))
            for line in log.read_text(errors="replace").splitlines()
            if " WARNING " in line or " ERROR " in line
        ]
        events = [
            f"{e['sim']:.1f} {e['kind']} {e['robot']} {e['task']} {e['detail']}"
            for e in self.events()
        ]
        text = report.read_text() if report.exists() else "(no report)"
        return "\n".join([text, *events, *warnings, self.output])


def battery_config(path: Path, **battery: float) -> Path:
    """The default configuration with ``robot.battery`` on and ``battery``'s fields set,
    written to ``path`` (for ``--config``)."""
    data = yaml.safe_load(default_config_path().read_text())
    data["robot"]["battery"].update(enabled=True, **battery)
    path.write_text(yaml.safe_dump(data))
    return path
