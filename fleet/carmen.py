"""CARMEN log files: parse ``PARAM``, ``FLASER``, ``RLASER``, ``ROBOTLASER1`` and ``ODOM`` lines;
write them.

The format is the CARMEN robot toolkit's text log, one message per line (the format of the
public SLAM datasets such as the Intel Research Lab, ACES and Freiburg 079 logs). Every message
line ends with ``ipc_timestamp ipc_hostname logger_timestamp``:

- ``PARAM name value ipc_timestamp ipc_hostname logger_timestamp``. Some writers leave out the
  IPC timestamp (``PARAM name value hostname logger_timestamp``) or the whole suffix
  (``PARAM name value``); the value is what remains once a trailing ``[number] host number`` is
  taken off. Numeric laser parameters are checked where they are read, and a bad one is an
  error naming its own line.
- ``FLASER n r1 … rn x y theta odom_x odom_y odom_theta timestamp hostname logger_timestamp``;
  ``x y theta`` is the laser's pose, ``odom_*`` the robot's raw odometry. ``RLASER`` is the
  same for the rear laser. The beams of the front laser span ``laser_front_laser_fov`` degrees
  starting at −fov/2, spaced by ``laser_front_laser_resolution`` degrees (rear:
  ``laser_rear_laser_*``). Without the fov, it is the resolution times the beam spacings
  (n−1 when n is odd, as 181 beams include both ends; n when even, as 180 beams at 1°); without
  either, 180°. ``robot_front_laser_max`` (``robot_rear_laser_max``) gives the maximum range
  (default 81.9 m, the SICK "no return").
- ``ROBOTLASER1 laser_type start_angle field_of_view angular_resolution maximum_range accuracy
  remission_mode n r1 … rn m e1 … em laser_x laser_y laser_theta robot_x robot_y robot_theta
  tv rv forward_safety_dist side_safety_dist turn_axis timestamp hostname logger_timestamp``:
  carries its own geometry.
- ``ODOM x y theta tv rv accel timestamp hostname logger_timestamp``.

Lines starting with ``#`` and empty lines are skipped; other message types (``SYNC``,
``TRUEPOS``, ``NEFF``, …) are counted and skipped. A broken last line (a log cut off while
recording) is dropped and reported; a broken line anywhere else raises ``CarmenParseError``
naming file and line. Files ending in ``.gz`` or starting with the gzip magic bytes are
decompressed transparently.
"""

from __future__ import annotations

import gzip
import math
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

import numpy as np

Pose = tuple[float, float, float]

FLASER_DEFAULT_FOV_DEG = 180.0
FLASER_DEFAULT_MAX_RANGE = 81.9
# PARAM names of the FLASER / RLASER geometry: (fov, resolution, maximum range), all numbers.
LASER_PARAMS = {
    "FLASER": (
        "laser_front_laser_fov",
        "laser_front_laser_resolution",
        "robot_front_laser_max",
    ),
    "RLASER": ("laser_rear_laser_fov", "laser_rear_laser_resolution", "robot_rear_laser_max"),
}
NUMERIC_PARAMS = frozenset(name for names in LASER_PARAMS.values() for name in names)


class CarmenParseError(ValueError):
    """A line of a CARMEN log cannot be parsed; the message starts with ``file:line:``."""

    def __init__(self, source: str, line: int, message: str) -> None:
        super().__init__(f"{source}:{line}: {message}")
        self.source = source
        self.line = line


@dataclass(frozen=True, eq=False)
class LaserRecord:
    """One scan: ranges with their angles, the laser's and the robot's odometry poses."""

    kind: str
    ranges: np.ndarray
    angle_min: float
    angle_increment: float
    max_range: float
    laser_pose: Pose
    robot_pose: Pose
    timestamp: float
    hostname: str
    logger_timestamp: float
    line: int


@dataclass(frozen=True)
class OdomRecord:
    pose: Pose
    tv: float
    rv: float
    accel: float
    timestamp: float
    hostname: str
    logger_timestamp: float
    line: int


@dataclass(frozen=True, eq=False)
class CarmenLog:
    records: list[LaserRecord | OdomRecord]
    params: dict[str, str]
    skipped: Counter = field(default_factory=Counter)
    truncated_line: int | None = None

    @property
    def scans(self) -> list[LaserRecord]:
        """Every laser record, front and rear, in log order."""
        return [r for r in self.records if isinstance(r, LaserRecord)]

    @property
    def front_scans(self) -> list[LaserRecord]:
        """The scans of one laser, for SLAM: all but ``RLASER`` ones, unless the log holds only
        rear scans (front and rear scans interleaved would be two sensors on one pose)."""
        scans = self.scans
        front = [r for r in scans if r.kind != "RLASER"]
        return front if front else scans


class _Tokens:
    """A cursor over one line's tokens that reports which field failed to parse."""

    def __init__(self, tokens: list[str], source: str, line: int) -> None:
        self.tokens = tokens
        self.i = 1
        self.source = source
        self.line = line

    def _next(self, what: str) -> str:
        if self.i >= len(self.tokens):
            raise CarmenParseError(
                self.source, self.line, f"{self.tokens[0]}: line ends before field {what!r}"
            )
        tok = self.tokens[self.i]
        self.i += 1
        return tok

    def float(self, what: str) -> float:
        tok = self._next(what)
        try:
            return float(tok)
        except ValueError:
            raise CarmenParseError(
                self.source, self.line, f"{self.tokens[0]}: field {what!r} is not a number: {tok!r}"
            ) from None

    def int(self, what: str) -> int:
        tok = self._next(what)
        try:
            value = int(tok)
        except ValueError:
            raise CarmenParseError(
                self.source,
                self.line,
                f"{self.tokens[0]}: field {what!r} is not an integer: {tok!r}",
            ) from None
        if value < 0:
            raise CarmenParseError(
                self.source, self.line, f"{self.tokens[0]}: field {what!r} is negative"
            )
        return value

    def str(self, what: str) -> str:
        return self._next(what)

    def floats(self, n: int, what: str) -> np.ndarray:
        if self.i + n > len(self.tokens):
            raise CarmenParseError(
                self.source, self.line, f"{self.tokens[0]}: line ends inside {what!r}"
            )
        chunk = self.tokens[self.i : self.i + n]
        try:
            values = np.array(chunk, dtype=float)
        except ValueError:
            raise CarmenParseError(
                self.source, self.line, f"{self.tokens[0]}: {what!r} holds a non-number"
            ) from None
        self.i += n
        return values

    def pose(self, what: str) -> Pose:
        return (self.float(f"{what}_x"), self.float(f"{what}_y"), self.float(f"{what}_theta"))

    def end(self) -> None:
        if self.i != len(self.tokens):
            raise CarmenParseError(
                self.source,
                self.line,
                f"{self.tokens[0]}: {len(self.tokens) - self.i} unexpected fields at the end",
            )


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def param_value(tokens: list[str]) -> str:
    """The value of a ``PARAM`` line split into ``tokens`` (``PARAM``, name, value…): the trailing
    ``[ipc_timestamp] hostname logger_timestamp`` is taken off when present (see the module
    docstring), and what is left, joined by spaces, is the value."""
    rest = tokens[2:]
    if len(rest) >= 3 and _is_number(rest[-1]) and not _is_number(rest[-2]):
        rest = rest[:-2]
        if len(rest) >= 2 and _is_number(rest[-1]):
            rest = rest[:-1]
    return " ".join(rest)


def _flaser(t: _Tokens, params: dict[str, float]) -> LaserRecord:
    kind = t.tokens[0]
    n = t.int("num_readings")
    ranges = t.floats(n, "range_readings")
    laser_pose = t.pose("laser")
    robot_pose = t.pose("odom")
    timestamp = t.float("timestamp")
    hostname = t.str("hostname")
    logger_timestamp = t.float("logger_timestamp")
    t.end()
    fov_name, resolution_name, max_name = LASER_PARAMS[kind]
    spacings = max(n - 1 if n % 2 else n, 1)
    if resolution_name in params:
        increment = math.radians(params[resolution_name])
        fov = math.radians(params.get(fov_name, params[resolution_name] * spacings))
    else:
        fov = math.radians(params.get(fov_name, FLASER_DEFAULT_FOV_DEG))
        increment = fov / spacings
    return LaserRecord(
        kind,
        ranges,
        -0.5 * fov,
        increment,
        params.get(max_name, FLASER_DEFAULT_MAX_RANGE),
        laser_pose,
        robot_pose,
        timestamp,
        hostname,
        logger_timestamp,
        t.line,
    )


def _robotlaser1(t: _Tokens) -> LaserRecord:
    t.int("laser_type")
    start = t.float("start_angle")
    t.float("field_of_view")
    resolution = t.float("angular_resolution")
    max_range = t.float("maximum_range")
    t.float("accuracy")
    t.int("remission_mode")
    n = t.int("num_readings")
    ranges = t.floats(n, "range_readings")
    m = t.int("num_remissions")
    t.floats(m, "remissions")
    laser_pose = t.pose("laser_pose")
    robot_pose = t.pose("robot_pose")
    for name in ("laser_tv", "laser_rv", "forward_safety_dist", "side_safety_dist", "turn_axis"):
        t.float(name)
    timestamp = t.float("timestamp")
    hostname = t.str("hostname")
    logger_timestamp = t.float("logger_timestamp")
    t.end()
    return LaserRecord(
        "ROBOTLASER1",
        ranges,
        start,
        resolution,
        max_range,
        laser_pose,
        robot_pose,
        timestamp,
        hostname,
        logger_timestamp,
        t.line,
    )


def _odom(t: _Tokens) -> OdomRecord:
    pose = t.pose("odom")
    tv, rv, accel = t.float("tv"), t.float("rv"), t.float("accel")
    timestamp = t.float("timestamp")
    hostname = t.str("hostname")
    logger_timestamp = t.float("logger_timestamp")
    t.end()
    return OdomRecord(pose, tv, rv, accel, timestamp, hostname, logger_timestamp, t.line)


def parse_lines(lines: Iterable[str], source: str = "<lines>") -> CarmenLog:
    """Parse CARMEN log lines (see the module docstring); ``source`` names them in errors."""
    records: list[LaserRecord | OdomRecord] = []
    params: dict[str, str] = {}
    numeric: dict[str, float] = {}
    skipped: Counter = Counter()
    pending: CarmenParseError | None = None
    for number, raw in enumerate(lines, start=1):
        text = raw.strip()
        if not text or text.startswith("#"):
            continue
        if pending is not None:
            raise pending
        tokens = text.split()
        kind = tokens[0]
        t = _Tokens(tokens, source, number)
        try:
            if kind == "PARAM":
                if len(tokens) < 3:
                    raise CarmenParseError(source, number, "PARAM needs a name and a value")
                value = param_value(tokens)
                if tokens[1] in NUMERIC_PARAMS:
                    if not _is_number(value):
                        raise CarmenParseError(
                            source, number, f"PARAM {tokens[1]} is not a number: {value!r}"
                        )
                    numeric[tokens[1]] = float(value)
                params[tokens[1]] = value
            elif kind in LASER_PARAMS:
                records.append(_flaser(t, numeric))
            elif kind == "ROBOTLASER1":
                records.append(_robotlaser1(t))
            elif kind == "ODOM":
                records.append(_odom(t))
            else:
                skipped[kind] += 1
        except CarmenParseError as e:
            pending = e
    truncated = pending.line if pending is not None else None
    return CarmenLog(records, params, skipped, truncated)


def open_text(path: str | Path, mode: str = "r") -> IO[str]:
    """Open a text file for reading or writing, gzip-compressed when it ends in ``.gz`` (or,
    for reading, when it starts with the gzip magic bytes)."""
    p = Path(path)
    if "r" in mode:
        with open(p, "rb") as f:
            magic = f.read(2)
        if magic == b"\x1f\x8b":
            return gzip.open(p, "rt", encoding="utf-8", errors="replace")
        return open(p, encoding="utf-8", errors="replace")
    if p.suffix == ".gz":
        return gzip.open(p, mode + "t", encoding="utf-8")
    return open(p, mode, encoding="utf-8")


def read_log(path: str | Path) -> CarmenLog:
    """Read a CARMEN log file (plain or gzip)."""
    try:
        with open_text(path) as f:
            return parse_lines(f, str(path))
    except (OSError, EOFError) as e:
        raise CarmenParseError(str(path), 0, f"cannot read: {e}") from None


def _fmt(values: Sequence[float] | np.ndarray, precision: int) -> str:
    return " ".join(f"{v:.{precision}f}" for v in values)


def format_param(
    name: str, value: str | float, timestamp: float = 0.0, hostname: str = "nohost"
) -> str:
    """A PARAM line with the ``ipc_timestamp ipc_hostname logger_timestamp`` suffix."""
    return f"PARAM {name} {value} {timestamp:.6f} {hostname} {timestamp:.6f}"


def format_flaser(
    ranges: np.ndarray,
    laser_pose: Pose,
    odom_pose: Pose,
    timestamp: float,
    hostname: str,
    logger_timestamp: float,
) -> str:
    """A FLASER line; readers assume 180° starting at −90° unless PARAM lines say otherwise."""
    return (
        f"FLASER {len(ranges)} {_fmt(ranges, 3)} {_fmt(laser_pose, 6)} {_fmt(odom_pose, 6)} "
        f"{timestamp:.6f} {hostname} {logger_timestamp:.6f}"
    )


def format_robotlaser1(
    ranges: np.ndarray,
    angle_min: float,
    angle_increment: float,
    max_range: float,
    laser_pose: Pose,
    robot_pose: Pose,
    timestamp: float,
    hostname: str,
    logger_timestamp: float,
    tv: float = 0.0,
    rv: float = 0.0,
) -> str:
    """A ROBOTLASER1 line: carries its own angles, so it suits any field of view (e.g. 360°)."""
    n = len(ranges)
    fov = angle_increment * n
    return (
        f"ROBOTLASER1 0 {angle_min:.6f} {fov:.6f} {angle_increment:.9f} {max_range:.3f} 0.01 0 "
        f"{n} {_fmt(ranges, 3)} 0 {_fmt(laser_pose, 6)} {_fmt(robot_pose, 6)} "
        f"{tv:.6f} {rv:.6f} 0 0 0 {timestamp:.6f} {hostname} {logger_timestamp:.6f}"
    )


def format_odom(
    pose: Pose,
    tv: float,
    rv: float,
    accel: float,
    timestamp: float,
    hostname: str,
    logger_timestamp: float,
) -> str:
    return (
        f"ODOM {_fmt(pose, 6)} {tv:.6f} {rv:.6f} {accel:.6f} {timestamp:.6f} {hostname} "
        f"{logger_timestamp:.6f}"
    )
