"""A picture of a coverage plan: the map, the regions in colour, the paths on top."""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw

from planners.grid import GridMap

_ROBOT_COLOURS = [(214, 39, 40), (31, 119, 180), (44, 160, 44), (148, 103, 189), (255, 127, 14)]


def render_plan(
    grid: GridMap,
    labels: np.ndarray,
    paths: list[np.ndarray],
    unreachable: np.ndarray | None = None,
    scale: int | None = None,
) -> Image.Image:
    """RGB image, north up: occupied black, unknown grey, each region a pale colour, free space
    no robot can clean hatched in red, robot paths as coloured polylines from a dot at the start."""
    rows, cols = grid.shape
    if scale is None:
        scale = max(1, min(6, 1600 // max(rows, cols)))
    rng = np.random.default_rng(7)
    palette = rng.integers(150, 240, size=(int(labels.max()) + 1, 3)).astype(np.uint8)
    img = np.full((rows, cols, 3), 255, dtype=np.uint8)
    img[labels > 0] = palette[labels[labels > 0]]
    img[grid.unknown] = (190, 190, 190)
    img[grid.occupied] = (0, 0, 0)
    if unreachable is not None:
        rr, cc = np.nonzero(unreachable)
        hatch = (rr + cc) % 3 == 0
        img[rr, cc] = np.where(hatch[:, None], (230, 80, 80), (250, 200, 200))
    pic = Image.fromarray(img[::-1]).resize((cols * scale, rows * scale), Image.NEAREST)
    draw = ImageDraw.Draw(pic)
    for i, path in enumerate(paths):
        if len(path) == 0:
            continue
        colour = _ROBOT_COLOURS[i % len(_ROBOT_COLOURS)]
        px = _to_pixels(grid, path, scale)
        if len(px) > 1:
            draw.line([tuple(p) for p in px], fill=colour, width=max(1, scale // 2))
        x, y = px[0]
        r = 2 * scale
        draw.ellipse([x - r, y - r, x + r, y + r], fill=colour, outline=(0, 0, 0))
    return pic


def _to_pixels(grid: GridMap, path: np.ndarray, scale: int) -> np.ndarray:
    rows = grid.shape[0]
    col = (path[:, 0] - grid.origin[0]) / grid.resolution
    row = (path[:, 1] - grid.origin[1]) / grid.resolution
    return np.stack([col * scale, (rows - row) * scale], axis=1)
