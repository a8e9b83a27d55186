"""Operator verbs on a running fleet, from another terminal: `fleet kill`, `fleet respawn`,
`fleet status`, `fleet down`.

Each reads the run dir's process table (``processes.json``, written by `fleet up`, see
:mod:`fleet.rundir`); `fleet status` also reads the coordinator's state file
(``coordinator.sqlite``) read-only, and the messages each process dropped (``dropped.json``).
By default they act on the newest run under ``runs/``.
"""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import time
from pathlib import Path
from typing import Annotated, Any

import typer

from fleet.cli.common import _fail
from fleet.cli.help_text import reflow
from fleet.rundir import (
    RunDirError,
    RunTable,
    is_alive,
    newest_run_dir,
    process_state,
    read_dropped,
    read_table,
)
from fleet.supervisor.ops import (
    STATE_FILE,
    OpsError,
    Sig,
    _up_state,
    ask_dock,
    ask_respawn,
    send_signal,
)

REPORT_FILE = "report.json"
DOWN_POLL_S = 0.2
DOWN_PROGRESS_S = 5.0
SQLITE_BUSY_S = 2.0
TASK_STATES = ("open", "assigned", "done")

RunDirOpt = Annotated[
    Path | None,
    typer.Option(
        "--run-dir",
        "-d",
        help="The run dir `fleet up` writes to (default: the newest one under runs/ that has a "
        "processes.json).",
    ),
]
NameArg = Annotated[
    str, typer.Argument(help="A robot id (e.g. robot-1) or 'coordinator'.", show_default=False)
]


def _table(run_dir: Path | None) -> tuple[Path, RunTable]:
    try:
        run_dir = run_dir if run_dir is not None else newest_run_dir()
        table = read_table(run_dir)
    except RunDirError as e:
        _fail(str(e))
    return run_dir, table


def kill(
    name: NameArg,
    sig: Annotated[
        Sig,
        typer.Option("--signal", "-s", case_sensitive=False, help="The signal to send."),
    ] = Sig.TERM,
    run_dir: RunDirOpt = None,
) -> None:
    """Send a signal to a robot's agent process or to the coordinator, as a fault would.

    TERM stops it cleanly, KILL stops it dead (no goodbye on the bus: its liveliness token
    lapses), STOP freezes it (a hung process: its heartbeats stop), CONT thaws a frozen one.
    The pid comes from the run's processes.json and is checked against /proc first, so a pid
    that now belongs to another program is never signalled.

    Examples: `fleet kill robot-1 --signal KILL`; `fleet kill coordinator`;
    `fleet kill robot-0 -s STOP`, later `fleet kill robot-0 -s CONT`.
    """
    run_dir, table = _table(run_dir)
    try:
        typer.echo(send_signal(run_dir, table, name, sig))
    except OpsError as e:
        _fail(str(e))


def respawn(
    name: NameArg,
    timeout: Annotated[
        float, typer.Option("--timeout", help="Seconds to wait for `fleet up` to answer.")
    ] = 10.0,
    run_dir: RunDirOpt = None,
) -> None:
    """Start a robot's agent or the coordinator again, after it died or was killed.

    `fleet up` restarts it with the arguments it had: an agent gets --respawn and reloads its
    map and last pose from its --state-dir (its robot is still in the world where it stopped);
    the coordinator resumes the job from its --state file. Refused while the process is still
    alive (running or stopped): kill it first. The log is appended to, not replaced.

    Example: `fleet kill robot-1 --signal KILL`, then `fleet respawn robot-1`.
    """
    if timeout <= 0:
        _fail(f"--timeout must be > 0 seconds, got {timeout}")
    run_dir, table = _table(run_dir)
    try:
        typer.echo(ask_respawn(run_dir, table, name, timeout, sender="cli"))
    except OpsError as e:
        _fail(str(e))


def dock(
    name: NameArg,
    to: Annotated[
        int | None,
        typer.Option(
            "--dock",
            help="The dock to send it to: its number among the world's docks, from 0, in the "
            "order the world file lists them (default: the one the coordinator picks).",
        ),
    ] = None,
    timeout: Annotated[
        float, typer.Option("--timeout", help="Seconds to wait for the coordinator to answer.")
    ] = 10.0,
    run_dir: RunDirOpt = None,
) -> None:
    """Send a robot home to a dock now, with robot.battery on.

    The coordinator takes its work back (the unswept rest of its task and its unstarted tasks
    go back to the market) and sends it to charge: by default to the dock it is on soonest,
    counting the robots ahead of it there, whose charge covers the trip (to wait by it while
    another robot holds it); with --dock, to that dock, waiting by it if it is held. The robot
    bids again once it has charged to robot.battery.recharge_to.

    Example: `fleet dock robot-1`, or `fleet dock robot-2 --dock 0`.
    """
    if timeout <= 0:
        _fail(f"--timeout must be > 0 seconds, got {timeout}")
    if to is not None and to < 0:
        _fail(f"--dock must be a dock's number, 0 or more, got {to}")
    _, table = _table(run_dir)
    try:
        typer.echo(ask_dock(table, name, timeout, sender="cli", dock=-1 if to is None else to))
    except OpsError as e:
        _fail(str(e))


def down(
    timeout: Annotated[
        float, typer.Option("--timeout", help="Seconds to wait for `fleet up` to finish.")
    ] = 60.0,
    run_dir: RunDirOpt = None,
) -> None:
    """Stop the whole fleet: send `fleet up` SIGTERM and wait while it collects the report
    (report.json, report.png) and stops every process, as Ctrl-C in its terminal would.

    Example: `fleet down`, or `fleet down --run-dir runs/20250101-120000 --timeout 120`.
    """
    if timeout <= 0:
        _fail(f"--timeout must be > 0 seconds, got {timeout}")
    run_dir, table = _table(run_dir)
    pid = table.up_pid
    if not is_alive(_up_state(table)):
        _fail(f"fleet up (pid {pid}) is not running; nothing to stop in {run_dir}")
    try:
        os.kill(pid, signal.SIGTERM)
        if _up_state(table) == "stopped":
            os.kill(pid, signal.SIGCONT)
    except ProcessLookupError:
        _fail(f"fleet up (pid {pid}) exited before it could be stopped")
    sent = time.time()
    typer.echo(f"sent SIGTERM to fleet up (pid {pid}); waiting up to {timeout:g} s")
    t0 = time.monotonic()
    last = t0
    while is_alive(_up_state(table)):
        now = time.monotonic()
        if now - t0 > timeout:
            _fail(
                f"fleet up (pid {pid}) has not stopped after {timeout:g} s; its log lines are on "
                f"its terminal, the processes' logs in {run_dir}/"
            )
        if now - last >= DOWN_PROGRESS_S:
            typer.echo(f"  still stopping after {now - t0:.0f} s (collecting the report)")
            last = now
        time.sleep(DOWN_POLL_S)
    report = run_dir / REPORT_FILE
    if not report.is_file() or report.stat().st_mtime < sent - 1.0:
        _fail(f"fleet up stopped without writing {report}; see the logs in {run_dir}/")
    typer.echo(f"fleet stopped after {time.monotonic() - t0:.1f} s; report: {report}")


def status(
    as_json: Annotated[
        bool,
        typer.Option(
            "--json",
            help="Print one JSON object: run_dir, fleet, endpoint; up {pid, state, malformed, "
            "implausible}; processes {name: {pid, state, restarts, started, log, malformed, "
            "implausible}}; coordinator (null until its state "
            "file exists) {phase, expected_robots, tasks {open, assigned, done}, robots {id: "
            "{liveness, state, task, progress, heartbeat_age_s, restarts}}}; coordinator_note "
            "(why coordinator is null, else empty). States: running, stopped, zombie, gone. "
            "malformed and implausible count the messages a process dropped (null: not told).",
        ),
    ] = False,
    run_dir: RunDirOpt = None,
) -> None:
    """Show every process of the fleet (running, stopped or gone, how often it was respawned,
    and how many messages it dropped as malformed or implausible) and the coordinator's view of
    the job: its phase, each robot's liveness, state, task, progress and heartbeat age, and how
    many tasks are open, assigned and done.

    Examples: `fleet status`; `fleet status --json | jq .coordinator.tasks`.
    """
    run_dir, table = _table(run_dir)
    result = collect_status(run_dir, table)
    if as_json:
        print(json.dumps(result))
        return
    from rich.console import Console

    console = Console()
    if console.is_terminal:
        _print_rich(console, result)
    else:
        print(_plain(result))


def collect_status(run_dir: Path, table: RunTable) -> dict[str, Any]:
    """What `fleet status --json` prints."""
    dropped = read_dropped(run_dir)

    def counts(name: str) -> dict[str, int | None]:
        malformed, implausible = dropped.get(name, (None, None))
        return {"malformed": malformed, "implausible": implausible}

    processes = {
        name: {
            "pid": p.pid,
            "state": process_state(p.pid, p.argv),
            "restarts": p.restarts,
            "started": p.started,
            "log": str(run_dir / p.log),
            **counts(name),
        }
        for name, p in table.processes.items()
    }
    coordinator, note = _coordinator_state(run_dir / STATE_FILE)
    return {
        "run_dir": str(run_dir),
        "fleet": table.fleet,
        "endpoint": table.endpoint,
        "up": {"pid": table.up_pid, "state": _up_state(table), **counts("up")},
        "processes": processes,
        "coordinator": coordinator,
        "coordinator_note": note,
    }


def _coordinator_state(path: Path) -> tuple[dict[str, Any] | None, str]:
    """The coordinator's state file, read-only, in one read transaction; or None and why."""
    if not path.is_file():
        return None, "not written yet"
    try:
        con = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True, timeout=SQLITE_BUSY_S)
    except sqlite3.Error as e:
        return None, f"cannot open {path}: {e}"
    try:
        con.isolation_level = None
        con.execute("BEGIN")
        meta = {k: _meta_value(v) for k, v in con.execute("SELECT key, value FROM meta")}
        counts = dict(con.execute("SELECT state, COUNT(*) FROM tasks GROUP BY state").fetchall())
        rows = con.execute(
            "SELECT id, liveness, state, task, progress, heartbeat_wall, restarts FROM robots "
            "ORDER BY id"
        ).fetchall()
        con.execute("COMMIT")
    except sqlite3.Error as e:
        return None, f"cannot read {path}: {e}"
    finally:
        con.close()
    now = time.time()
    robots = {
        rid: {
            "liveness": liveness,
            "state": state,
            "task": task,
            "progress": progress,
            "heartbeat_age_s": None if beat is None else round(now - beat, 1),
            "restarts": restarts,
        }
        for rid, liveness, state, task, progress, beat, restarts in rows
    }
    expected = meta.get("expected_robots")
    return {
        "phase": meta.get("phase"),
        "expected_robots": expected if isinstance(expected, int) else None,
        "tasks": {s: counts.get(s, 0) for s in TASK_STATES},
        "robots": robots,
    }, ""


def _meta_value(text: str | None) -> Any:
    """A meta value: the coordinator stores JSON (``"cleaning"``, ``3``); plain text is kept."""
    if text is None:
        return None
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def _cell(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.2f}"
    return str(value)


PROCESS_COLUMNS = ("process", "pid", "state", "restarts", "malformed", "implausible")
ROBOT_COLUMNS = ("robot", "liveness", "state", "task", "progress", "heartbeat s", "restarts")
ROBOT_FIELDS = ("liveness", "state", "task", "progress", "heartbeat_age_s", "restarts")


def _rows(result: dict[str, Any]) -> tuple[list[list[str]], list[list[str]]]:
    procs = [
        [name, str(p["pid"]), p["state"], str(p["restarts"])]
        + [_cell(p[k]) for k in ("malformed", "implausible")]
        for name, p in result["processes"].items()
    ]
    coord = result["coordinator"] or {"robots": {}}
    robots = [[rid, *(_cell(r[k]) for k in ROBOT_FIELDS)] for rid, r in coord["robots"].items()]
    return procs, robots


def _headline(result: dict[str, Any]) -> tuple[str, str]:
    up = result["up"]
    head = f"fleet {result['fleet']} in {result['run_dir']}: fleet up pid {up['pid']} {up['state']}"
    coord = result["coordinator"]
    if coord is None:
        return head, f"coordinator state: {result['coordinator_note']}"
    t = coord["tasks"]
    return head, (
        f"coordinator: phase {_cell(coord['phase'])}; tasks open {t['open']}, assigned "
        f"{t['assigned']}, done {t['done']}"
    )


def _plain(result: dict[str, Any]) -> str:
    head, coord_line = _headline(result)
    procs, robots = _rows(result)
    lines = [head, *_columns([list(PROCESS_COLUMNS), *procs]), coord_line]
    if robots:
        lines += _columns([list(ROBOT_COLUMNS), *robots])
    return "\n".join(lines)


def _columns(rows: list[list[str]]) -> list[str]:
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows]


def _print_rich(console: Any, result: dict[str, Any]) -> None:
    from rich.table import Table

    head, coord_line = _headline(result)
    procs, robots = _rows(result)
    console.print(head)
    console.print(_rich_table(Table, PROCESS_COLUMNS, procs))
    console.print(coord_line)
    if robots:
        console.print(_rich_table(Table, ROBOT_COLUMNS, robots))


def _rich_table(table_cls: type, columns: tuple[str, ...], rows: list[list[str]]) -> Any:
    table = table_cls(*columns)
    for row in rows:
        table.add_row(*row)
    return table


def register(
    app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app: typer.Typer
) -> None:
    commands = (("kill", kill), ("respawn", respawn), ("dock", dock), ("status", status))
    for name, command in (*commands, ("down", down)):
        app.command(name, help=reflow(command.__doc__ or ""))(command)
