"""What several command modules share: the helpers that check options, load parameters, open
the bus, log and stop on signals, and tell a bench's progress and result (the shared options
are in ``fleet/cli/options.py``)."""

from __future__ import annotations

import json
import signal
import sys
import threading
from collections.abc import Callable
from datetime import datetime
from pathlib import Path
from typing import Any

import typer

from fleet.bus import DEFAULT_ENDPOINT


def _check_deconfliction(mode: str | None) -> None:
    """Exit with status 2 unless ``--deconfliction`` is unset or one of the modes (checked
    before any process starts; the mode list comes with the parameters, imported only here)."""
    from fleet.params import DECONFLICTION_MODES

    if mode is not None and mode not in DECONFLICTION_MODES:
        _fail(f"--deconfliction must be one of {', '.join(DECONFLICTION_MODES)}, got {mode!r}")


def _fail(message: str) -> None:
    typer.secho(f"error: {message}", fg=typer.colors.RED, err=True)
    raise typer.Exit(2)


def parse_seeds(text: str) -> list[int]:
    """``--seeds``: ``0,1,2`` or ``0-4`` (inclusive), or a mix (``0-2,7``); exits naming the
    bad part."""
    out: list[int] = []
    for part in text.split(","):
        part = part.strip()
        lo, sep, hi = part.partition("-")
        try:
            out += list(range(int(lo), int(hi) + 1)) if sep else [int(part)]
        except ValueError:
            _fail(f"--seeds: {part!r} is not a seed or a range like 0-4")
    if not out:
        _fail("--seeds: no seed given")
    return out


def world_file(world: str, option: str = "") -> str:
    """The file of ``--world`` (a built-in name or a path); exits naming what is wrong,
    after ``option`` when given (``--worlds: ...``)."""
    from fleet.config import ConfigError, resolve_world

    try:
        path = resolve_world(world)
    except ConfigError as e:
        _fail(f"{option}: {e}" if option else str(e))
    return str(path)


def stamped_dir(given: Path | None, pattern: str) -> Path:
    """``given``, else runs/ and the time now as ``pattern`` (strftime) says:
    ``bench-fleet-%Y%m%d-%H%M%S``."""
    return given or Path("runs") / datetime.now().strftime(pattern)


def progress_line(line: str) -> None:
    """A line of a bench's progress, on stderr at once (stdout is the result)."""
    print(line, file=sys.stderr, flush=True)


def print_result(
    result: dict[str, Any], as_json: bool, table_lines: Callable[[dict[str, Any]], list[str]]
) -> None:
    """A bench's result on stdout: one JSON object, or the lines of its table."""
    if as_json:
        print(json.dumps(result))
    else:
        typer.echo("\n".join(table_lines(result)))


def _setup_logging(name: str) -> None:
    import logging
    import sys

    logging.basicConfig(
        level=logging.INFO,
        stream=sys.stderr,
        format=f"%(asctime)s {name} %(levelname)s %(message)s",
        datefmt="%H:%M:%S",
    )


def _stop_on_signals(event: threading.Event) -> None:
    def handler(signum: int, _frame: object) -> None:
        event.set()

    signal.signal(signal.SIGTERM, handler)
    signal.signal(signal.SIGINT, handler)


def _load(config: Path | None, world: str | None = None):
    from fleet.config import ConfigError, resolve_world
    from fleet.params import load_fleet_config
    from fleet.world import load_world

    try:
        cfg = load_fleet_config(config)
        w = load_world(resolve_world(world), cfg.robot.radius) if world is not None else None
    except ConfigError as e:
        _fail(str(e))
    return cfg, w


def _bus(
    role: str,
    ident: str,
    connect: list[str] | None,
    fleet: str,
    zenoh_config: Path | None = None,
):
    from fleet.bus import Bus

    try:
        return Bus(
            role, ident, connect or [DEFAULT_ENDPOINT], fleet=fleet, zenoh_config=zenoh_config
        )
    except ValueError as e:
        _fail(str(e))
    except Exception as e:  # zenoh raises ZError for unreachable routers
        _fail(f"cannot connect to {connect or [DEFAULT_ENDPOINT]}: {e}")
