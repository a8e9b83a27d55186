"""Lane placement on one lattice per room, with extra lanes only where the lattice leaves floor.

Lanes lie between two rows of the room's rotated frame (half-integer row coordinates) and sweep
exactly ``step`` rows each. Placing every cell's lanes on one lattice per room (row
coordinates ``phase + k·step``) means cells stacked on each other never sweep the same strip:
the lattice lane that straddles the border between a cell and the cell above belongs to the
lower cell and spans where both rows are reachable. A cell adds a lane off the lattice (a clamp
lane, as close to the wall as the uncovered floor needs and only as long as it) only where
cleanable floor it owns lies below its first or above its last lattice lane — typically along a
wall. Where the cell's width changes (a shoulder beside furniture or a doorway: the lattice lane
stops short of a wall that steps out), a short shoulder lane, as close to the missed floor as the
cell allows and only as long as it, sweeps each patch of at least ``SHOULDER_CELLS`` missed
cells; shoulder lanes are tasks of their own, so the tour reaches them from whichever lane end
is nearest. What is left (mostly single cells at lane ends) is for targeted fill-in passes.
The phase is chosen per room among the ``step`` possible ones to minimise the total lane
length.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from planners.coverage.bcd import MonotoneCell
from planners.coverage.sweeps import lane_extent
from planners.grid import extend_labels

SHOULDER_CELLS = 20
# what a separate task costs beyond its lane, in cells of lane length, when choosing the phase
TASK_COST_CELLS = 20


def room_lanes(
    cells: list[MonotoneCell],
    rot: np.ndarray,
    clean_rot: np.ndarray,
    cell_labels_rot: np.ndarray,
    step: int,
    half_width: float,
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per cell an (n, 3) array of lanes ``(y, first col, last col)`` sorted by ``y``, and per
    cell an (m, 3) array of its shoulder lanes.

    ``rot`` is the room's robot-centre mask in its rotated frame, ``clean_rot`` the cleanable
    floor the room is responsible for, ``cell_labels_rot`` the cells' label image (1..n) and
    ``half_width`` the swath half-width in cells.
    """
    if not cells:
        return [], []
    owner = extend_labels(cell_labels_rot, clean_rot)
    rmin = min(c.row0 for c in cells)
    best: tuple[float, tuple[list[np.ndarray], list[np.ndarray]]] | None = None
    for shift in range(step):
        lanes = _lanes_for_phase(cells, rot, clean_rot, owner, rmin + 0.5 + shift, step, half_width)
        cost = float(
            sum((ln[:, 2] - ln[:, 1] + 1).sum() + TASK_COST_CELLS * len(ln) for ln in lanes[1])
            + sum((ln[:, 2] - ln[:, 1] + 1).sum() + len(ln) for ln in lanes[0])
        )
        if best is None or cost < best[0]:
            best = (cost, lanes)
    assert best is not None
    return best[1]


def _lanes_for_phase(
    cells, rot, clean_rot, owner, phase, step, hw
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    lattice: list[list[tuple[float, int, int]]] = []
    covered = np.zeros(rot.shape, dtype=bool)
    for cell in cells:
        lanes = _lattice_lanes(cell, rot, phase, step)
        for y, lo, hi in lanes:
            _sweep(covered, y, lo, hi, hw)
        lattice.append(lanes)
    out = []
    for k, (cell, lanes) in enumerate(zip(cells, lattice, strict=True), start=1):
        mine = clean_rot & (owner == k) & ~covered
        for below in (True, False):
            ys = [ln[0] for ln in lanes]
            lane = _clamp_lane(cell, mine, ys, below, hw)
            if lane is not None:
                _sweep(covered, *lane, hw)
                mine &= ~covered
                lanes.append(lane)
        lanes.sort()
        out.append(np.array(lanes, dtype=float).reshape(-1, 3))
    shoulders = []
    for k, cell in enumerate(cells, start=1):
        mine = clean_rot & (owner == k) & ~covered
        extra = _shoulder_lanes(cell, mine, hw)
        for lane in extra:
            _sweep(covered, *lane, hw)
        shoulders.append(np.array(extra, dtype=float).reshape(-1, 3))
    return out, shoulders


def _shoulder_lanes(cell: MonotoneCell, mine: np.ndarray, hw: float) -> list:
    """Short lanes sweeping the patches of ``mine`` (the cell's missed floor) of at least
    ``SHOULDER_CELLS`` cells, largest first: each at the row where the cell's lane sweeps most
    of it (ties to rows within two of touching the patch's lower or upper edge), as long as
    the patch."""
    labels, n = ndimage.label(mine, structure=np.ones((3, 3)))
    if n == 0:
        return []
    sizes = np.bincount(labels.ravel())[1:]
    boxes = ndimage.find_objects(labels)
    reach = math.ceil(hw - 1e-9) - 0.5
    top = cell.row0 + cell.rows - 1
    out = []
    left = mine.copy()
    for lab in np.argsort(-sizes) + 1:
        if sizes[lab - 1] < SHOULDER_CELLS:
            break
        box = boxes[lab - 1]
        rr, cc = np.nonzero((labels[box] == lab) & left[box])
        if len(rr) < SHOULDER_CELLS:
            continue
        rr, cc = rr + box[0].start, cc + box[1].start
        best = None
        edges = [w + d for w in (rr.min() + reach, rr.max() - reach) for d in (0, 1, -1, 2, -2)]
        # then every row that reaches the patch: a strip along a wall joined to the floor of a
        # doorway above it is swept from below the doorway, where the lane runs the full length
        wants = [*edges, *np.arange(rr.min() - reach, rr.max() + reach + 1).tolist()]
        c_lo, c_hi = int(cc.min()) - 1, int(cc.max()) + 1
        for want in wants:
            if cell.rows == 1:
                y = float(cell.row0)
            else:
                y = float(min(max(want, cell.row0 + 0.5), top - 0.5))
            lo, hi = lane_extent(cell, y)
            if lo > hi:
                continue
            first = min(max(c_lo, lo), hi)
            last = min(max(c_hi, lo), hi)
            got = (np.abs(rr - y) < hw - 1e-9) & (cc >= first - 2) & (cc <= last + 2)
            if best is None or got.sum() > best[0]:
                best = (int(got.sum()), (y, first, last))
        if best is None or best[0] < SHOULDER_CELLS:
            continue
        out.append(best[1])
        left[_band(left.shape, *best[1], hw)] = False
    return out


def _lattice_lanes(cell: MonotoneCell, rot: np.ndarray, phase: float, step: int):
    """The lattice lanes inside the cell, and the one straddling its top border if any."""
    if cell.rows == 1:
        return [(float(cell.row0), int(cell.left[0]), int(cell.right[0]))]
    top = cell.row0 + cell.rows - 1
    k0 = math.ceil((cell.row0 + 0.5 - phase) / step - 1e-9)
    lanes = []
    y = phase + k0 * step
    while y <= top - 0.5 + 1e-9:
        lo, hi = lane_extent(cell, y)
        if lo <= hi:
            lanes.append((float(y), lo, hi))
        y += step
    if abs(y - (top + 0.5)) < 1e-9 and top + 1 < rot.shape[0]:
        span = _single_run(rot[top + 1], int(cell.left[-1]), int(cell.right[-1]))
        if span is not None:
            lanes.append((float(y), *span))
    return lanes


def _single_run(row: np.ndarray, lo: int, hi: int) -> tuple[int, int] | None:
    """The run of ``row[lo..hi]`` if there is exactly one: where the row above splits (an
    obstacle begins), each part is left to its own cell and to this cell's top clamp lane."""
    seg = np.concatenate([[False], row[lo : hi + 1], [False]]).astype(np.int8)
    d = np.diff(seg)
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1
    if len(starts) != 1:
        return None
    return lo + int(starts[0]), lo + int(ends[0])


def _clamp_lane(cell: MonotoneCell, mine: np.ndarray, ys: list[float], below: bool, hw: float):
    """A lane covering the cell's uncovered floor below its first lane (or above its last)."""
    rr, cc = np.nonzero(mine)
    if len(rr) == 0:
        return None
    reach = math.ceil(hw - 1e-9) - 0.5
    if ys:
        sel = rr < min(ys) - reach if below else rr > max(ys) + reach
        rr, cc = rr[sel], cc[sel]
    if len(rr) == 0:
        return None
    top = cell.row0 + cell.rows - 1
    if cell.rows == 1:
        y = float(cell.row0)
        lo, hi = int(cell.left[0]), int(cell.right[0])
    else:
        want = rr.min() + reach if below else rr.max() - reach
        y = float(np.clip(want, cell.row0 + 0.5, top - 0.5))
        lo, hi = lane_extent(cell, y)
    if lo > hi:
        return None
    first = int(np.clip(cc.min() - 1, lo, hi))
    last = int(np.clip(cc.max() + 1, lo, hi))
    return (y, first, last)


def _sweep(covered: np.ndarray, y: float, lo: int, hi: int, hw: float) -> None:
    """Mark the cells within ``hw`` across the lane from (y, lo) to (y, hi), and up to ``hw``
    beyond its ends: the swath's round ends leave corners the turns and fill-in passes take."""
    covered[_band(covered.shape, y, lo, hi, hw)] = True


def _band(shape: tuple[int, int], y: float, lo: int, hi: int, hw: float) -> tuple[slice, slice]:
    """The rows within ``hw`` of the lane at ``y`` × its columns widened by ``hw`` − 1."""
    rows, cols = shape
    n = math.ceil(hw - 1e-9) - 1
    r0, r1 = max(0, math.floor(y - hw)), min(rows, math.ceil(y + hw) + 1)
    rr = np.arange(r0, r1, dtype=float)
    band = rr[np.abs(rr - y) < hw - 1e-9].astype(int)
    if not len(band):
        return slice(0, 0), slice(0, 0)
    return slice(band[0], band[-1] + 1), slice(max(0, lo - n), min(cols, hi + n + 1))
