"""Small synthetic grids for the coverage tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from planners.grid import GridMap

RES = 0.05
DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "maps"


def boxed(rows: int, cols: int, res: float = RES) -> np.ndarray:
    """Occupancy of a rows × cols grid with a one-cell wall all around."""
    occ = np.zeros((rows, cols), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    return occ


def grid_of(occ: np.ndarray, unknown: np.ndarray | None = None, res: float = RES) -> GridMap:
    return GridMap(occ, np.zeros_like(occ) if unknown is None else unknown, res, (0.0, 0.0))


def furnished(seed: int) -> GridMap:
    """A 5 m × 4 m room with a partition wall, a doorway and random boxes as furniture."""
    rng = np.random.default_rng(seed)
    occ = boxed(80, 100)
    occ[:, 50] = True
    occ[30:50, 50] = False
    for _ in range(4):
        r, c = rng.integers(10, 65), rng.integers(5, 85)
        occ[r : r + rng.integers(4, 14), c : c + rng.integers(4, 14)] = True
    return grid_of(occ)


def write_ros_map(folder: Path, pixels: np.ndarray, **fields) -> Path:
    """A ROS map_server YAML + PGM (pixels: 254 free, 0 occupied, 205 unknown; row 0 = top)."""
    from PIL import Image

    Image.fromarray(pixels.astype(np.uint8)).save(folder / "map.pgm")
    meta = {
        "image": "map.pgm",
        "resolution": RES,
        "origin": [0.0, 0.0, 0.0],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
    }
    meta.update(fields)
    lines = [f"{k}: {v}" for k, v in meta.items()]
    path = folder / "map.yaml"
    path.write_text("\n".join(lines) + "\n")
    return path


def open_spots(grid: GridMap, k: int, spacing: float = 0.5) -> list[tuple[float, float]]:
    """``k`` points with the most clearance, at least ``spacing`` apart."""
    from planners.grid import clearance

    clear = clearance(grid)
    order = np.argsort(clear.ravel(), kind="stable")[::-1]
    pts = grid.cell_to_world(np.stack(np.unravel_index(order, clear.shape), axis=1))
    out: list[tuple[float, float]] = []
    for p in pts:
        if all(np.hypot(p[0] - q[0], p[1] - q[1]) >= spacing for q in out):
            out.append((float(p[0]), float(p[1])))
            if len(out) == k:
                break
    return out
