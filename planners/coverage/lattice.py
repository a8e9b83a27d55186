"""Lanes in continuous coordinates on one lattice per room, with extra lanes only where the
lattice leaves floor.

Swaths are laid out in continuous coordinates, as Fields2Cover (Mier et al. 2023) does, inside
the cells of a boustrophedon decomposition (Choset 2000): a lane is ``(y, first col, last col)``
in the room's rotated frame, ``y`` any real row coordinate, and the lattice lanes of a room lie
at ``phase + k·spacing``, ``spacing`` being the robot's ``cleaning_width · (1 − overlap)`` in
rows, not rounded to whole rows. A robot centre may take a lane at ``y`` where both rows next to
it (``floor(y)`` and ``ceil(y)``) are robot-centre cells (``sweeps.lane_extent``): every point of
the lane then lies in the square of a robot-centre cell.

Placing every cell's lanes on one lattice per room means cells stacked on each other never sweep
the same strip: the lattice lane between the top row of a cell and the row above belongs to the
lower cell and spans where both rows are reachable. The room's phase is the one of least total
lane length (shoulder lanes priced as separate tasks) among the phases that balance one of its
cells' lattice in its reachable band (the first and the last lane equally far inside it) and
the phases that put a lane on every whole row: balancing alone leaves a margin at both walls,
which often costs a clamp lane at each where a lattice laid against one wall needs one (measured
in BENCHMARKS.md at f9accd2, "After, final"); ties go to the balanced phases. A cell
adds a lane off the lattice (a clamp lane, as close to the wall as the uncovered floor needs and
only as long as it) only where cleanable floor it owns lies below its first or above its last
lattice lane — typically along a wall. Where the cell's width changes (a shoulder beside
furniture or a doorway: the lattice lane stops short of a wall that steps out), a short shoulder
lane, as close to the missed floor as the cell allows and only as long as it, sweeps each patch
of at least ``SHOULDER_CELLS`` missed cells; shoulder lanes are tasks of their own, so the tour
reaches them from whichever lane end is nearest. What is left (mostly single cells at lane ends)
is for targeted fill-in passes.

A room of many cells proposes many phases, most of which lay the lattice lanes between the same
rows as another (they differ by fractions of a row): a phase is priced only when its lattice
decisions (``_decisions``) are new, and each cell's clamp and shoulder lanes are looked for in
the box of the floor it owns, not in the whole room.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from planners.coverage.bcd import MonotoneCell
from planners.coverage.sweeps import lane_extent
from planners.grid import extend_labels

SHOULDER_CELLS = 20
# what a separate task costs beyond its lane, in cells of lane length, when choosing the phase
TASK_COST_CELLS = 20
# lane row coordinates this close to a whole row are that row (a lane on a row needs only it)
_ROW_SNAP = 1e-6


@dataclass(frozen=True, eq=False)
class RoomLanes:
    """A room's lanes, per cell (n, 3) arrays ``(y, first col, last col)`` sorted by ``y``:
    ``lattice`` its lanes on the room's lattice (``phase + k·spacing``, in rows), ``clamps``
    its lanes off the lattice along its walls, ``shoulders`` its shoulder lanes."""

    lattice: tuple[np.ndarray, ...]
    clamps: tuple[np.ndarray, ...]
    shoulders: tuple[np.ndarray, ...]
    phase: float
    spacing: float

    def lanes(self) -> list[np.ndarray]:
        """Per cell its lattice and clamp lanes together, sorted by ``y``: its boustrophedon."""
        out = []
        for lat, cl in zip(self.lattice, self.clamps, strict=True):
            both = np.vstack([lat, cl])
            out.append(both[np.argsort(both[:, 0], kind="stable")])
        return out


def room_lanes(
    cells: list[MonotoneCell],
    rot: np.ndarray,
    clean_rot: np.ndarray,
    cell_labels_rot: np.ndarray,
    spacing: float,
    half_width: float,
) -> RoomLanes:
    """The room's lanes, ``spacing`` rows apart on one lattice (the phase of least total lane
    length, ties to a balanced one).

    ``rot`` is the room's robot-centre mask in its rotated frame, ``clean_rot`` the cleanable
    floor the room is responsible for, ``cell_labels_rot`` the cells' label image (1..n) and
    ``half_width`` the swath half-width, both in rows.
    """
    if not cells:
        return RoomLanes((), (), (), 0.0, spacing)
    owner = extend_labels(cell_labels_rot, clean_rot)
    # each cell's floor in the bounding box of what it owns: a room's phases × cells work on
    # cell-sized arrays, not room-sized ones
    boxes = ndimage.find_objects(owner, max_label=len(cells))
    owned = [
        _Owned((0, 0), np.zeros((0, 0), dtype=bool))
        if box is None
        else _Owned((box[0].start, box[1].start), clean_rot[box] & (owner[box] == k))
        for k, box in enumerate(boxes, start=1)
    ]
    best: tuple[float, RoomLanes] | None = None
    seen: set[tuple] = set()
    for phase in _phases(cells, spacing):
        lattice = [_lattice_lanes(cell, rot, phase, spacing) for cell in cells]
        decisions = _decisions(lattice, rot.shape, half_width)
        if decisions in seen:
            # the same lanes as an earlier phase's, but for where they lie between their rows,
            # and the same cost: that earlier phase keeps the tie
            continue
        seen.add(decisions)
        lanes = _lanes_for_phase(cells, lattice, owned, phase, spacing, half_width, rot.shape)
        cost = _cost(lanes.shoulders, TASK_COST_CELLS) + _cost(lanes.lanes(), 1)
        if best is None or cost < best[0] - 1e-9:
            best = (cost, lanes)
    assert best is not None
    return best[1]


@dataclass(frozen=True)
class _Owned:
    """The cleanable floor a cell owns, cropped to its bounding box at ``origin`` (row, col)."""

    origin: tuple[int, int]
    floor: np.ndarray

    def window(self, img: np.ndarray) -> np.ndarray:
        """``img`` (room-sized) over this box."""
        (r, c), (h, w) = self.origin, self.floor.shape
        return img[r : r + h, c : c + w]


def _cost(lanes: Sequence[np.ndarray], per_lane: float) -> float:
    """Total length of ``lanes`` in cells, plus ``per_lane`` cells for each."""
    return float(sum((ln[:, 2] - ln[:, 1] + 1).sum() + per_lane * len(ln) for ln in lanes))


def _phases(cells: list[MonotoneCell], spacing: float) -> list[float]:
    """Candidate lattice phases in ``[0, spacing)``: per cell (largest first) the two that
    centre its lattice lanes in its reachable band, both margins equal — with as many lanes as
    fit (margins under half a spacing) and with one fewer (margins of half to one spacing,
    which its clamp lanes share evenly at the two walls); then those that put a lane on every
    whole row from the room's first row on (half a row above it, as lanes between two rows)."""
    phases: list[float] = []
    for cell in sorted(cells, key=lambda c: -c.cells):
        height = cell.rows - 1
        margin = (height - math.floor(height / spacing + 1e-9) * spacing) / 2
        for p in (cell.row0 + margin, cell.row0 + margin + spacing / 2):
            p = math.fmod(p, spacing)
            if all(min(abs(p - q), spacing - abs(p - q)) > _ROW_SNAP for q in phases):
                phases.append(p)
    first = min(c.row0 for c in cells)
    for k in range(math.ceil(spacing)):
        p = math.fmod(first + 0.5 + k, spacing)
        if all(min(abs(p - q), spacing - abs(p - q)) > _ROW_SNAP for q in phases):
            phases.append(p)
    return phases


def _lanes_for_phase(
    cells: list[MonotoneCell],
    lattice: list[list[tuple[float, int, int]]],
    owned: list[_Owned],
    phase: float,
    spacing: float,
    hw: float,
    shape: tuple[int, int],
) -> RoomLanes:
    """The room's lanes given its ``lattice`` lanes at ``phase``: the clamp and shoulder lanes
    for the floor they leave."""
    covered = np.zeros(shape, dtype=bool)
    for lanes in lattice:
        for y, lo, hi in lanes:
            _sweep(covered, y, lo, hi, hw)
    clamps = []
    for cell, lanes, own in zip(cells, lattice, owned, strict=True):
        mine = own.floor & ~own.window(covered)
        extra: list[tuple[float, int, int]] = []
        for below in (True, False):
            ys = [ln[0] for ln in lanes + extra]
            lane = _clamp_lane(cell, mine, own.origin, ys, below, hw)
            if lane is not None:
                _sweep(covered, *lane, hw)
                mine &= ~own.window(covered)
                extra.append(lane)
        clamps.append(extra)
    shoulders = []
    for cell, own in zip(cells, owned, strict=True):
        mine = own.floor & ~own.window(covered)
        extra = _shoulder_lanes(cell, mine, own.origin, covered.shape, hw)
        for lane in extra:
            _sweep(covered, *lane, hw)
        shoulders.append(extra)
    return RoomLanes(
        tuple(_array(ln) for ln in lattice),
        tuple(_array(ln) for ln in clamps),
        tuple(_array(ln) for ln in shoulders),
        phase,
        spacing,
    )


def _decisions(lattice: list[list[tuple[float, int, int]]], shape: tuple[int, int], hw: float):
    """All that the clamp and shoulder lanes and the cost take from a phase's lattice lanes:
    per lane its columns, the rows either side of it, the rows its swath covers and the last
    rows a clamp lane beyond it may take (``_clamp_lane``). Phases alike in all of it differ
    only in where their lattice lanes lie between the same rows."""
    out = []
    for lanes in lattice:
        for y, lo, hi in lanes:
            rows, _ = _band(shape, y, lo, hi, hw)
            out.append(
                (
                    lo,
                    hi,
                    math.floor(y),
                    math.ceil(y),
                    rows.start,
                    rows.stop,
                    math.floor(y - hw + 1e-9),
                    math.ceil(y + hw - 1e-9),
                )
            )
        out.append(())
    return tuple(out)


def _array(lanes: list[tuple[float, int, int]]) -> np.ndarray:
    return np.array(sorted(lanes), dtype=float).reshape(-1, 3)


def _centre_band(cell: MonotoneCell) -> tuple[float, float]:
    """The row coordinates a lane of the cell may take: its first to its last row."""
    return float(cell.row0), float(cell.row0 + cell.rows - 1)


def _shoulder_lanes(
    cell: MonotoneCell,
    mine: np.ndarray,
    origin: tuple[int, int],
    shape: tuple[int, int],
    hw: float,
) -> list:
    """Short lanes sweeping the patches of ``mine`` (the cell's missed floor, a window at
    ``origin`` of the room's ``shape``) of at least
    ``SHOULDER_CELLS`` cells, largest first: each at the row where the cell's lane sweeps most
    of it (ties to rows within two of touching the patch's lower or upper edge), as long as
    the patch."""
    if mine.sum() < SHOULDER_CELLS:
        return []
    labels, _ = ndimage.label(mine, structure=np.ones((3, 3)))
    sizes = np.bincount(labels.ravel())[1:]
    boxes = ndimage.find_objects(labels)
    reach = hw - 0.5
    bottom, top = _centre_band(cell)
    out = []
    left = mine.copy()
    for lab in np.argsort(-sizes) + 1:
        if sizes[lab - 1] < SHOULDER_CELLS:
            break
        box = boxes[lab - 1]
        rr, cc = np.nonzero((labels[box] == lab) & left[box])
        if len(rr) < SHOULDER_CELLS:
            continue
        rr, cc = rr + box[0].start + origin[0], cc + box[1].start + origin[1]
        lane = _shoulder_lane(cell, rr, cc, bottom, top, reach, hw)
        if lane is None:
            continue
        out.append(lane)
        rows, cols = _band(shape, *lane, hw)
        r0, c0 = origin
        left[_shift(rows, r0), _shift(cols, c0)] = False
    return out


def _shoulder_lane(
    cell: MonotoneCell,
    rr: np.ndarray,
    cc: np.ndarray,
    bottom: float,
    top: float,
    reach: float,
    hw: float,
) -> tuple[float, int, int] | None:
    """The lane of the cell sweeping most of the patch at rows ``rr``, columns ``cc`` (the
    first such row of those tried, see :func:`_shoulder_lanes`), if it sweeps at least
    ``SHOULDER_CELLS`` of it."""
    edges = [w + d for w in (rr.min() + reach, rr.max() - reach) for d in (0, 1, -1, 2, -2)]
    # then every row that reaches the patch: a strip along a wall joined to the floor of a
    # doorway above it is swept from below the doorway, where the lane runs the full length
    wants = np.array([*edges, *np.arange(rr.min() - reach, rr.max() + reach + 1).tolist()])
    ys = np.minimum(np.maximum(wants, bottom), top)
    a = np.floor(ys).astype(int) - cell.row0
    b = np.ceil(ys).astype(int) - cell.row0
    lo = np.maximum(cell.left[a], cell.left[b])
    hi = np.minimum(cell.right[a], cell.right[b])
    c_lo, c_hi = int(cc.min()) - 1, int(cc.max()) + 1
    first = np.minimum(np.maximum(c_lo, lo), hi)
    last = np.minimum(np.maximum(c_hi, lo), hi)
    got = (
        (np.abs(rr[None, :] - ys[:, None]) < hw - 1e-9)
        & (cc[None, :] >= first[:, None] - 2)
        & (cc[None, :] <= last[:, None] + 2)
    ).sum(axis=1)
    got = np.where(lo <= hi, got, -1)
    k = int(np.argmax(got))
    if got[k] < SHOULDER_CELLS:
        return None
    return float(ys[k]), int(first[k]), int(last[k])


def _lattice_lanes(
    cell: MonotoneCell, rot: np.ndarray, phase: float, spacing: float
) -> list[tuple[float, int, int]]:
    """The lattice lanes inside the cell, and the one between its top row and the row above
    if any."""
    if cell.rows == 1:
        return [(float(cell.row0), int(cell.left[0]), int(cell.right[0]))]
    bottom, top = _centre_band(cell)
    k = math.ceil((bottom - phase) / spacing - 1e-9)
    lanes = []
    while True:
        y = _snap(phase + k * spacing)
        if y > top:
            break
        lo, hi = lane_extent(cell, y)
        if lo <= hi:
            lanes.append((y, lo, hi))
        k += 1
    row = int(top) + 1
    if y < row and row < rot.shape[0]:
        span = _single_run(rot[row], int(cell.left[-1]), int(cell.right[-1]))
        if span is not None:
            lanes.append((y, *span))
    return lanes


def _snap(y: float) -> float:
    r = round(y)
    return float(r) if abs(y - r) < _ROW_SNAP else y


def _single_run(row: np.ndarray, lo: int, hi: int) -> tuple[int, int] | None:
    """The run of ``row[lo..hi]`` if there is exactly one: where the row above splits (an
    obstacle begins), each part is left to its own cell and to this cell's top clamp lane."""
    seg = np.concatenate([[False], row[lo : hi + 1], [False]]).astype(np.int8)
    d = np.diff(seg)
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1
    if len(starts) != 1:
        return None
    return lo + int(starts[0]), lo + int(ends[0])


def _clamp_lane(
    cell: MonotoneCell,
    mine: np.ndarray,
    origin: tuple[int, int],
    ys: list[float],
    below: bool,
    hw: float,
):
    """A lane covering the cell's uncovered floor (``mine``, a window at ``origin``) below its
    first lane (or above its last)."""
    rr, cc = np.nonzero(mine)
    if len(rr) == 0:
        return None
    rr, cc = rr + origin[0], cc + origin[1]
    reach = hw - 0.5
    if ys:
        # the rows the nearest lane leaves: at least hw away from it
        sel = rr <= min(ys) - hw + 1e-9 if below else rr >= max(ys) + hw - 1e-9
        rr, cc = rr[sel], cc[sel]
    if len(rr) == 0:
        return None
    bottom, top = _centre_band(cell)
    if cell.rows == 1:
        y = bottom
        lo, hi = int(cell.left[0]), int(cell.right[0])
    else:
        want = rr.min() + reach if below else rr.max() - reach
        y = float(np.clip(want, bottom, top))
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


def _shift(s: slice, by: int) -> slice:
    """A room-frame slice in a window starting at ``by`` (clipped at the window's start)."""
    return slice(max(0, s.start - by), max(0, s.stop - by))
