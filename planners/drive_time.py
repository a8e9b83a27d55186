"""How long a differential-drive robot takes to drive a polyline that it stops at to turn.

The model: the robot stops at every *stop* vertex (a sharp turn), turns in place there by the
heading change, and drives each straight run between stops from rest to rest with a
trapezoidal velocity profile — accelerating at ``accel`` up to ``speed``, cruising, braking at
``accel`` (a triangular profile when the run is too short to reach ``speed``: peak
``√(accel·L)``, time ``2√(L/accel)``). Turning in place by θ follows the same profile in the
angle with ``turn_rate`` and ``turn_accel``. Vertices that are not stops are driven through at
speed. This prices what a constant-speed estimate misses on a boustrophedon path: every lane
end is a stop, a short hop to the next lane (0.27 m takes 1.5 s from rest to rest at 0.5 m/s²,
not 0.54 s at 0.5 m/s) and two turns in place.
"""

from __future__ import annotations

import itertools

import numpy as np


def profile_time(distance: np.ndarray, top: float, accel: float) -> np.ndarray:
    """Seconds to cover each ``distance`` from rest to rest (trapezoidal or triangular)."""
    d = np.asarray(distance, dtype=float)
    ramp = top * top / accel  # distance of a full speed-up plus a full braking
    return np.where(d >= ramp, d / top + top / accel, 2.0 * np.sqrt(np.maximum(d, 0.0) / accel))


def time_into_run(s: np.ndarray, length: float, top: float, accel: float) -> np.ndarray:
    """Seconds from the start of a rest-to-rest run of ``length`` to distance ``s`` along it."""
    s = np.clip(np.asarray(s, dtype=float), 0.0, length)
    peak = min(top, float(np.sqrt(accel * length)))
    ramp = peak * peak / (2.0 * accel)  # distance of the speed-up (and of the braking)
    total = float(profile_time(np.array(length), top, accel))
    up = np.sqrt(2.0 * s / accel)
    cruise = peak / accel + (s - ramp) / peak if peak > 0 else np.zeros_like(s)
    down = total - np.sqrt(2.0 * np.maximum(length - s, 0.0) / accel)
    return np.where(s <= ramp, up, np.where(s >= length - ramp, down, cruise))


def vertex_times(
    points: np.ndarray,
    stops: np.ndarray,
    turns: np.ndarray,
    speed: float,
    accel: float,
    turn_rate: float,
    turn_accel: float,
) -> np.ndarray:
    """Seconds from the start to each vertex of ``points`` ((N, 2)), arriving there.

    ``stops`` (N booleans) marks the interior vertices the robot stops and turns in place at;
    ``turns`` (N) the heading change (rad) it turns there. The first and last vertices are
    stops (the robot starts and ends at rest). A turn at a vertex counts after the arrival
    there, so it belongs to what follows the vertex.
    """
    pts = np.asarray(points, dtype=float)
    n = len(pts)
    out = np.zeros(n)
    if n < 2:
        return out
    seg = np.hypot(*np.diff(pts, axis=0).T)
    along = np.concatenate([[0.0], np.cumsum(seg)])
    ends = np.flatnonzero(np.asarray(stops, dtype=bool))
    ends = np.unique(np.concatenate([[0], ends, [n - 1]]))
    spin = profile_time(np.asarray(turns, dtype=float), turn_rate, turn_accel)
    t0 = 0.0
    for a, b in itertools.pairwise(ends):
        if a > 0:
            t0 += float(spin[a])
        length = float(along[b] - along[a])
        run = time_into_run(along[a + 1 : b + 1] - along[a], length, speed, accel)
        out[a + 1 : b + 1] = t0 + run
        t0 = float(out[b])
    return out
