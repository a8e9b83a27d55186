"""What a robot keeps on disk across a restart of its software: its SLAM map and its last pose.

Both live in one uncompressed ``.npz`` (``slam_state.npz``) that is written to a temporary file
in the same directory and then renamed over the old one with ``os.replace``, so a process killed
mid-write leaves the previous state intact, and map and pose always belong together. The arrays
are stored raw (no pickling): the map's log-odds as ``SlamMap`` holds them, its resolution and
origin, the pose (x, y, θ) in the map frame, and the time the pose was valid.

The pose alone is also written far more often than the map, to ``slam_pose.json`` (same
temporary-file-and-rename scheme), because a restarted robot searches for itself around its last
known pose: the staler that pose, the wider the search and the likelier a look-alike place
within it (a rectangular room turned by half a turn). ``load_state`` takes the newer of the two
poses.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from agents.slam.slam_map import SlamMap

Pose = tuple[float, float, float]

STATE_FILE = "slam_state.npz"
POSE_FILE = "slam_pose.json"
FORMAT_VERSION = 1


class StateError(ValueError):
    """The saved state is missing, unreadable or inconsistent; the message names the file."""


@dataclass(frozen=True, eq=False)
class SavedState:
    """A map and the pose in its frame at ``stamp`` (sim time), as last saved."""

    occupancy: SlamMap
    pose: Pose
    stamp: float


def state_path(directory: Path) -> Path:
    return Path(directory) / STATE_FILE


def _replace_atomically(directory: Path, name: str, write) -> None:
    """``write(file)`` into a temporary file in ``directory`` (created if missing), then rename
    it over ``directory / name``; a failure leaves the old file as it was."""
    directory.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.replace(tmp, directory / name)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def save_pose(directory: Path, pose: Pose, stamp: float) -> None:
    """Write the pose (map frame) and its stamp atomically to ``directory / POSE_FILE``."""
    record = {"pose": [float(v) for v in pose], "stamp": float(stamp)}
    _replace_atomically(Path(directory), POSE_FILE, lambda f: f.write(json.dumps(record).encode()))


def save_state(directory: Path, occupancy: SlamMap, pose: Pose, stamp: float) -> None:
    """Write map, pose and stamp atomically into ``directory`` (created if missing)."""

    def write(f) -> None:
        np.savez(
            f,
            version=np.array(FORMAT_VERSION, dtype=np.int64),
            log_odds=np.ascontiguousarray(occupancy.log_odds),
            resolution=np.array(occupancy.resolution, dtype=np.float64),
            origin=np.array(occupancy.origin, dtype=np.float64),
            pose=np.array(pose, dtype=np.float64),
            stamp=np.array(stamp, dtype=np.float64),
        )

    _replace_atomically(Path(directory), STATE_FILE, write)


def load_state(directory: Path) -> SavedState:
    """The state ``save_state`` wrote into ``directory``, with the pose ``save_pose`` wrote there
    when it is newer; ``StateError`` naming the file if either is missing (the pose file may
    be), unreadable, of another format version or inconsistent."""
    path = state_path(directory)
    if not path.is_file():
        raise StateError(f"{path}: no saved SLAM state")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise StateError(f"{path}: unreadable ({exc})") from exc
    missing = {"version", "log_odds", "resolution", "origin", "pose", "stamp"} - set(arrays)
    if missing:
        raise StateError(f"{path}: missing {', '.join(sorted(missing))}")
    if arrays["version"].shape != () or int(arrays["version"]) != FORMAT_VERSION:
        raise StateError(f"{path}: format version {arrays['version']}, expected {FORMAT_VERSION}")
    log_odds = arrays["log_odds"]
    if log_odds.ndim != 2 or log_odds.size == 0 or log_odds.dtype.kind != "f":
        raise StateError(f"{path}: log_odds must be a non-empty 2-D float array")
    if not np.isfinite(log_odds).all():
        raise StateError(f"{path}: log_odds holds non-finite values")
    shapes = {"resolution": (), "origin": (2,), "pose": (3,), "stamp": ()}
    for name, shape in shapes.items():
        a = arrays[name]
        if a.shape != shape or a.dtype.kind != "f" or not np.isfinite(a).all():
            raise StateError(f"{path}: {name} must be finite floats of shape {shape}")
    resolution = float(arrays["resolution"])
    if resolution <= 0:
        raise StateError(f"{path}: resolution must be > 0")
    if not -math.pi - 1e-9 <= float(arrays["pose"][2]) <= math.pi + 1e-9:
        raise StateError(f"{path}: pose heading must be within [-pi, pi]")
    ox, oy = (float(v) for v in arrays["origin"])
    x, y, theta = (float(v) for v in arrays["pose"])
    occupancy = SlamMap(log_odds, resolution, (ox, oy))
    pose, stamp = (x, y, theta), float(arrays["stamp"])
    newer = _load_pose(Path(directory) / POSE_FILE)
    if newer is not None and newer[1] > stamp:
        pose, stamp = newer
    return SavedState(occupancy, pose, stamp)


def _load_pose(path: Path) -> tuple[Pose, float] | None:
    """The pose and stamp in ``path`` (``save_pose``'s file), None if there is no such file."""
    if not path.is_file():
        return None
    try:
        record = json.loads(path.read_text())
        x, y, theta = (float(v) for v in record["pose"])
        stamp = float(record["stamp"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise StateError(f"{path}: unreadable pose ({exc})") from exc
    if not all(math.isfinite(v) for v in (x, y, theta, stamp)):
        raise StateError(f"{path}: pose and stamp must be finite")
    if not -math.pi - 1e-9 <= theta <= math.pi + 1e-9:
        raise StateError(f"{path}: pose heading must be within [-pi, pi]")
    return (x, y, theta), stamp
