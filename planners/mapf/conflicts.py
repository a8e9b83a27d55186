"""Finding the conflicts between agents' paths, vectorized over time with numpy.

Paths are padded with their last cell (agents stay at their goals), so a vertex conflict at a
time after one agent's arrival is a target conflict. A conflict is a tuple
``(t, a, b, u, v)``: a vertex conflict has ``v == -1`` and both agents in cell ``u`` at time t;
an edge (swap) conflict has agent ``a`` moving ``u → v`` and ``b`` moving ``v → u``, arriving at t.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

Conflict = tuple[int, int, int, int, int]


def positions(paths: Sequence[Sequence[int]], length: int | None = None) -> np.ndarray:
    """(agents, T) array of cells, each path padded with its last cell up to T."""
    horizon = max(len(p) for p in paths) if length is None else length
    out = np.empty((len(paths), horizon), dtype=np.int64)
    for i, p in enumerate(paths):
        out[i, : len(p)] = p
        out[i, len(p) :] = p[-1]
    return out


def conflicts_of(agent: int, path: Sequence[int], others: np.ndarray) -> list[Conflict]:
    """All conflicts between ``path`` (as agent ``agent``) and every other row of ``others``."""
    _k, horizon = others.shape
    length = max(horizon, len(path))
    if length > horizon:
        others = np.pad(others, ((0, 0), (0, length - horizon)), mode="edge")
    row = np.empty(length, dtype=np.int64)
    row[: len(path)] = path
    row[len(path) :] = path[-1]
    vert = others == row
    vert[agent] = False
    moving = row[1:] != row[:-1]
    swap = (others[:, :-1] == row[1:]) & (others[:, 1:] == row[:-1]) & moving
    swap[agent] = False
    out: list[Conflict] = []
    bs, ts = np.nonzero(vert)
    out.extend(
        zip(
            ts.tolist(),
            [agent] * len(ts),
            bs.tolist(),
            row[ts].tolist(),
            [-1] * len(ts),
            strict=False,
        )
    )
    bs, ts = np.nonzero(swap)
    if len(ts):
        out.extend(
            zip(
                (ts + 1).tolist(),
                [agent] * len(ts),
                bs.tolist(),
                row[ts].tolist(),
                row[ts + 1].tolist(),
                strict=False,
            )
        )
    return out


def all_conflicts(paths: Sequence[Sequence[int]]) -> list[Conflict]:
    """Every conflict between every pair of paths, each reported once with ``a < b``."""
    pos = positions(paths)
    out: list[Conflict] = []
    for a, p in enumerate(paths):
        out.extend(c for c in conflicts_of(a, p, pos) if c[2] > a)
    return out
