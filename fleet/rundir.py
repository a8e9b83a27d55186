"""The run dir of a fleet: its process table, and whether a process named in it still runs.

``fleet up`` writes ``<run_dir>/processes.json`` each time it starts or restarts a process, so
the operator verbs (``fleet kill``, ``respawn``, ``status``, ``down``) can act on a running
fleet from another terminal:

```
{"fleet": "default", "endpoint": "tcp/127.0.0.1:40123", "up_pid": 4242,
 "up_cmdline": ["/usr/bin/python3", "/usr/bin/fleet", "up", ...], "world": "/.../home.yaml",
 "processes": {"robot-0": {"pid": 4250, "argv": ["agent", "--id", "robot-0", ...],
                           "started": 1718000000.5, "restarts": 0, "log": "robot-0.log"}}}
```

``argv`` holds the arguments after ``python -m fleet.cli``; ``up_cmdline`` is the whole command
line of ``fleet up`` itself. A pid is only trusted while ``/proc/<pid>/cmdline`` still shows
that command line, so a pid the kernel has given to another program is never signalled.

``fleet up`` also writes ``<run_dir>/dropped.json`` whenever the counts change: the messages
each process has dropped as malformed and as implausible, as the processes tell them on the
bus (``implausible`` is null for a process that does not count them):

```
{"sim": {"malformed": 0, "implausible": 3}, "robot-0": {"malformed": 1, "implausible": 2}}
```
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

TABLE_NAME = "processes.json"
DROPPED_NAME = "dropped.json"
RUNS_ROOT = Path("runs")
CLI_MODULE = "fleet.cli"
# /proc/<pid>/stat states: T stopped by a signal, t stopped by a tracer, Z zombie, X dead.
STOPPED_STATES = ("T", "t")
DEAD_STATES = ("X", "x")


class RunDirError(Exception):
    """A run dir or its process table that cannot be used; the message names the path."""


@dataclass
class ProcessRecord:
    """One process ``fleet up`` started: its pid now, how to start it again, its log."""

    pid: int
    argv: list[str]
    started: float
    restarts: int = 0
    log: str = ""


@dataclass
class RunTable:
    """The content of ``processes.json``."""

    fleet: str
    endpoint: str
    up_pid: int
    world: str
    processes: dict[str, ProcessRecord] = field(default_factory=dict)
    up_cmdline: list[str] = field(default_factory=list)

    def robots(self) -> list[str]:
        """The robot processes' names (every process started as ``fleet agent``)."""
        return [n for n, p in self.processes.items() if p.argv[:1] == ["agent"]]


# process name -> (malformed, implausible) messages it dropped; implausible None if not told
Dropped = dict[str, tuple[int, int | None]]


def write_table(run_dir: Path, table: RunTable) -> Path:
    """Write ``run_dir/processes.json`` atomically: a reader sees the old table or the new one,
    never a part of one."""
    return _write_json(run_dir / TABLE_NAME, asdict(table))


def write_dropped(run_dir: Path, dropped: Dropped) -> Path:
    """Write ``run_dir/dropped.json`` atomically."""
    counts = {name: {"malformed": m, "implausible": i} for name, (m, i) in dropped.items()}
    return _write_json(run_dir / DROPPED_NAME, counts)


def read_dropped(run_dir: Path) -> Dropped:
    """What ``run_dir/dropped.json`` holds; empty if there is none (yet) or it cannot be read
    (the counts then show as unknown)."""
    try:
        raw = read_json_object(run_dir / DROPPED_NAME, RunDirError)
    except RunDirError:
        return {}
    out: Dropped = {}
    for name, counts in raw.items():
        if isinstance(counts, dict) and isinstance(counts.get("malformed"), int):
            implausible = counts.get("implausible")
            out[name] = (counts["malformed"], implausible if isinstance(implausible, int) else None)
    return out


def _write_json(path: Path, value: Any) -> Path:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(value, f, indent=1)
            f.write("\n")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def read_json_object(path: Path, error: type[Exception]) -> dict[str, Any]:
    """The JSON object in ``path``; ``error`` naming the file if it cannot be read, is not JSON
    or holds something else than an object."""
    try:
        raw = json.loads(path.read_text())
    except FileNotFoundError:
        raise error(f"{path} does not exist") from None
    except (OSError, UnicodeDecodeError) as e:
        raise error(f"cannot read {path}: {e}") from None
    except json.JSONDecodeError as e:
        raise error(f"{path} is not valid JSON: {e}") from None
    if not isinstance(raw, dict):
        raise error(f"{path}: expected a JSON object, got {type(raw).__name__}")
    return raw


def read_table(run_dir: Path) -> RunTable:
    """Read and check ``run_dir/processes.json``; raises RunDirError naming the file and field."""
    if not run_dir.is_dir():
        raise RunDirError(f"no such run dir: {run_dir}")
    path = run_dir / TABLE_NAME
    if not path.exists():
        raise RunDirError(f"no fleet was started in {run_dir} (no {TABLE_NAME})")
    raw = read_json_object(path, RunDirError)
    procs = _field(raw, "processes", dict, path)
    return RunTable(
        fleet=_field(raw, "fleet", str, path),
        endpoint=_field(raw, "endpoint", str, path),
        up_pid=_pid(_field(raw, "up_pid", int, path), "up_pid", path),
        world=_field(raw, "world", str, path),
        processes={name: _record(name, p, path) for name, p in procs.items()},
        up_cmdline=_strings(raw.get("up_cmdline", []), "up_cmdline", path),
    )


def _field(raw: dict[str, Any], key: str, kind: type, path: Path, where: str = "") -> Any:
    if key not in raw:
        raise RunDirError(f"{path}: missing field {where}{key}")
    value = raw[key]
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if not isinstance(value, kind) or isinstance(value, bool):
        raise RunDirError(f"{path}: field {where}{key} must be {kind.__name__}, got {value!r}")
    return value


def _pid(value: int, name: str, path: Path) -> int:
    if value <= 0:
        raise RunDirError(f"{path}: field {name} must be a pid > 0, got {value}")
    return value


def _strings(value: Any, name: str, path: Path) -> list[str]:
    if not isinstance(value, list) or not all(isinstance(a, str) for a in value):
        raise RunDirError(f"{path}: field {name} must be a list of strings")
    return value


def _record(name: str, raw: Any, path: Path) -> ProcessRecord:
    where = f"processes.{name}."
    if not isinstance(raw, dict):
        raise RunDirError(f"{path}: field processes.{name} must be an object")
    return ProcessRecord(
        pid=_pid(_field(raw, "pid", int, path, where), f"{where}pid", path),
        argv=_strings(_field(raw, "argv", list, path, where), f"{where}argv", path),
        started=_field(raw, "started", float, path, where),
        restarts=_field(raw, "restarts", int, path, where),
        log=_field(raw, "log", str, path, where),
    )


def newest_run_dir(root: Path = RUNS_ROOT) -> Path:
    """The most recently modified directory under ``root`` that holds a process table."""
    try:
        dirs = [d for d in root.iterdir() if (d / TABLE_NAME).is_file()]
    except FileNotFoundError:
        raise RunDirError(f"no run dir: {root}/ does not exist; pass --run-dir") from None
    except NotADirectoryError:
        raise RunDirError(f"{root} is not a directory; pass --run-dir") from None
    if not dirs:
        raise RunDirError(f"no fleet was started under {root}/ (no */{TABLE_NAME}); pass --run-dir")
    return max(dirs, key=lambda d: (d / TABLE_NAME).stat().st_mtime)


def cmdline(pid: int) -> list[str] | None:
    """The arguments of process ``pid``, or None when there is no such process."""
    try:
        raw = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return None
    return raw.decode(errors="replace").split("\0")[:-1]


def _stat_state(pid: int) -> str | None:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[1].split()[0]


def runs_as(args: list[str], argv: list[str]) -> bool:
    """Whether the command line ``args`` is ``argv`` itself, or runs ``fleet.cli`` with exactly
    ``argv``."""
    if args == argv:
        return True
    return CLI_MODULE in args and args[args.index(CLI_MODULE) + 1 :] == argv


def process_state(pid: int, argv: list[str]) -> str:
    """``running``, ``stopped`` (SIGSTOP), ``zombie`` (exited, not yet reaped) or ``gone``.

    A pid whose command line is no longer ``argv`` (see :func:`runs_as`) is ``gone``: the
    process that had it has exited and the kernel gave the number to another."""
    state = _stat_state(pid)
    if state is None or state in DEAD_STATES:
        return "gone"
    if state == "Z":
        return "zombie"
    args = cmdline(pid)
    if args is None or not runs_as(args, argv):
        return "gone"
    return "stopped" if state in STOPPED_STATES else "running"


def is_alive(state: str) -> bool:
    """A running or stopped process still holds its robot: it must not be started twice."""
    return state in ("running", "stopped")
