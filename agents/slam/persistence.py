"""What a robot keeps on disk across a restart of its software: its SLAM map and its last pose.

Both live in one uncompressed ``.npz`` (``slam_state.npz``) that is written to a temporary file
in the same directory and then renamed over the old one with ``os.replace``, so a process killed
mid-write leaves the previous state intact, and map and pose always belong together. The arrays
are stored raw (no pickling): the map's log-odds as ``SlamMap`` holds them, its resolution and
origin, the pose (x, y, θ) in the map frame, and the time the pose was valid.
"""

from __future__ import annotations

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


def save_state(directory: Path, occupancy: SlamMap, pose: Pose, stamp: float) -> None:
    """Write map, pose and stamp atomically into ``directory`` (created if missing)."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".slam_state.", suffix=".npz.tmp", dir=directory)
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(
                f,
                version=np.array(FORMAT_VERSION, dtype=np.int64),
                log_odds=np.ascontiguousarray(occupancy.log_odds),
                resolution=np.array(occupancy.resolution, dtype=np.float64),
                origin=np.array(occupancy.origin, dtype=np.float64),
                pose=np.array(pose, dtype=np.float64),
                stamp=np.array(stamp, dtype=np.float64),
            )
        os.replace(tmp, state_path(directory))
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def load_state(directory: Path) -> SavedState:
    """The state ``save_state`` wrote into ``directory``; ``StateError`` naming the file if it is
    missing, unreadable, of another format version or inconsistent."""
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
    return SavedState(occupancy, (x, y, theta), float(arrays["stamp"]))
