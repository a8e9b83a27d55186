"""What each stretch of a coverage tour is: a lane, a turn between lanes, another sweeping
pass, or a hop between passes, along the tour's arc length.

A tour (``planners.coverage.plan_coverage``'s path for one robot) drives its sweep passes in
order, with a hop (a straight or A* transit) from the end of each to the start of the next.
Its vertices are simplified (straight runs as one segment), so a pass may begin or end inside a
segment; elements are therefore arc-length intervals, not vertex ranges.

Within a pass, a segment runs *along the lane axis* when its direction is within
``AXIS_TOLERANCE_DEG`` of the pass's room's lane direction. A pass that runs along its axis
for at least ``LANE_SHARE`` of its length is a lane pass (a lane piece): its axis segments are
``lane`` elements and the rest ``turn`` elements. Every other pass (fill-in passes, return
strips) is one ``pass`` element. Lane elements that continue one another on one straight line
(a lane cut into pieces) share a ``run`` id: the same lane.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import networkx as nx
import numpy as np

from planners.coverage import CoveragePlan
from planners.coverage.tour import path_of

ELEMENT_KINDS = ("lane", "turn", "pass", "hop")
LANE, TURN, PASS, HOP = range(4)
AXIS_TOLERANCE_DEG = 10.0
LANE_SHARE = 0.6
# a pass's ends are the tour's vertices or points on its segments, equal up to rounding
MATCH_TOLERANCE_M = 1e-6
# lane pieces of one lane meet end to end on one line, to rounding
SAME_LINE_M = 1e-3


@dataclass(frozen=True, eq=False)
class TourElements:
    """The elements of one tour, in driving order: element i covers arc lengths
    ``start_m[i]`` to ``end_m[i]`` of the tour, is of kind ``ELEMENT_KINDS[kind[i]]``, belongs
    to lane run ``run[i]`` (lanes on one line share it; any other element has its own), and for
    a hop ``hop_m[i]`` is its length (0 for the other kinds). The intervals do not overlap and
    cover the tour but for zero-length gaps."""

    start_m: np.ndarray
    end_m: np.ndarray
    kind: np.ndarray
    run: np.ndarray
    hop_m: np.ndarray

    def __len__(self) -> int:
        return len(self.start_m)

    def at(self, s: np.ndarray) -> np.ndarray:
        """The element at each arc length of ``s`` (the later one at a boundary; -1 outside
        the tour)."""
        s = np.asarray(s, dtype=float)
        if len(self) == 0:
            return np.full(s.shape, -1, dtype=np.int64)
        i = np.searchsorted(self.start_m, s, side="right") - 1
        inside = (i >= 0) & (s <= self.end_m[np.clip(i, 0, None)] + MATCH_TOLERANCE_M)
        return np.where(inside, i, -1)

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (:meth:`from_json` reads it back)."""
        return {
            "kinds": list(ELEMENT_KINDS),
            "start_m": self.start_m.tolist(),
            "end_m": self.end_m.tolist(),
            "kind": self.kind.tolist(),
            "run": self.run.tolist(),
            "hop_m": self.hop_m.tolist(),
        }

    @classmethod
    def from_json(cls, obj: Any) -> TourElements:
        """Read :meth:`to_json`'s dict; ValueError naming the field that is wrong."""
        if not isinstance(obj, dict):
            raise ValueError("tour elements must be an object")
        if obj.get("kinds") != list(ELEMENT_KINDS):
            raise ValueError(f"field kinds must be {list(ELEMENT_KINDS)}, got {obj.get('kinds')}")
        arrays = {}
        for name, dtype in (
            ("start_m", float),
            ("end_m", float),
            ("kind", np.int64),
            ("run", np.int64),
            ("hop_m", float),
        ):
            try:
                arrays[name] = np.asarray(obj[name], dtype=dtype).reshape(-1)
            except KeyError:
                raise ValueError(f"missing field {name}") from None
            except (TypeError, ValueError):
                raise ValueError(f"field {name} must be a list of numbers") from None
        n = len(arrays["start_m"])
        if any(len(a) != n for a in arrays.values()):
            raise ValueError("fields start_m, end_m, kind, run, hop_m must have one length")
        if n and (arrays["kind"].min() < 0 or arrays["kind"].max() >= len(ELEMENT_KINDS)):
            raise ValueError("field kind holds a code outside kinds")
        if np.any(np.diff(arrays["start_m"]) < 0) or np.any(arrays["end_m"] < arrays["start_m"]):
            raise ValueError("fields start_m, end_m must be ordered intervals")
        return cls(**arrays)


def tour_elements(
    path: np.ndarray,
    passes: Sequence[Sequence[np.ndarray]],
    axes: Sequence[float | None],
) -> TourElements:
    """The elements of ``path``, a tour driving ``passes`` in order (each given as its
    candidate paths: the ways the tour may have driven it, e.g. each variant and its reverse),
    ``axes[i]`` the lane direction (radians) of pass i's room, None where it has none.

    Each pass is found on the path after the one before it: the first place where one of its
    candidates starts and, its length further along, ends. ValueError when a pass is not
    found, so a tour that is not made of these passes cannot be mislabelled."""
    pts = np.asarray(path, dtype=float).reshape(-1, 2)
    if len(pts) < 2:
        raise ValueError(f"a tour needs at least 2 points, got {len(pts)}")
    if len(passes) != len(axes):
        raise ValueError(f"{len(passes)} passes but {len(axes)} axes")
    seg = np.diff(pts, axis=0)
    seg_len = np.hypot(*seg.T)
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    out = _Builder()
    cursor = 0.0
    for i, (candidates, axis) in enumerate(zip(passes, axes, strict=True)):
        found = _find(pts, seg, seg_len, cum, candidates, cursor)
        if found is None:
            raise ValueError(f"pass {i} is not on the tour after {cursor:.3f} m")
        s0, driven = found
        out.hop(cursor, s0)
        cursor = out.drive(s0, driven, axis)
    return out.result()


def locate(path: np.ndarray, sub: np.ndarray) -> float | None:
    """The arc length along ``path`` where ``sub`` begins, ``sub`` running along ``path``
    from there for its whole length (its first such place); None when it does not."""
    pts = np.asarray(path, dtype=float).reshape(-1, 2)
    if len(pts) < 2:
        return None
    seg = np.diff(pts, axis=0)
    seg_len = np.hypot(*seg.T)
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    found = _find(pts, seg, seg_len, cum, [np.asarray(sub, dtype=float)], 0.0)
    return None if found is None else found[0]


def _find(
    pts: np.ndarray,
    seg: np.ndarray,
    seg_len: np.ndarray,
    cum: np.ndarray,
    candidates: Sequence[np.ndarray],
    cursor: float,
) -> tuple[float, np.ndarray] | None:
    """(arc length where the pass begins, the candidate driven): the earliest start at or
    after ``cursor`` whose candidate ends its own length further along the tour."""
    best: tuple[float, np.ndarray] | None = None
    first = max(int(np.searchsorted(cum, cursor, side="right")) - 2, 0)
    for cand in candidates:
        c = np.asarray(cand, dtype=float).reshape(-1, 2)
        rel = c[0] - pts[first:-1]
        along = np.clip(
            np.einsum("ij,ij->i", rel, seg[first:]) / np.maximum(seg_len[first:] ** 2, 1e-18),
            0.0,
            1.0,
        )
        gap = np.hypot(*(rel - along[:, None] * seg[first:]).T)
        starts = cum[first:-1] + along * seg_len[first:]
        ok = (gap < MATCH_TOLERANCE_M) & (starts >= cursor - MATCH_TOLERANCE_M)
        if not ok.any():
            continue
        s0 = starts[ok]
        length = float(np.hypot(*np.diff(c, axis=0).T).sum())
        ends = _point_at(pts, seg, seg_len, cum, s0 + length)
        hit = np.hypot(*(ends - c[-1]).T) < MATCH_TOLERANCE_M * max(1.0, len(c))
        hit &= s0 + length <= cum[-1] + MATCH_TOLERANCE_M
        if hit.any():
            s = float(s0[np.argmax(hit)])
            if best is None or s < best[0]:
                best = (s, c)
    return best


def _point_at(
    pts: np.ndarray, seg: np.ndarray, seg_len: np.ndarray, cum: np.ndarray, s: np.ndarray
) -> np.ndarray:
    """The tour's points at arc lengths ``s``."""
    j = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)
    f = np.clip((s - cum[j]) / np.maximum(seg_len[j], 1e-18), 0.0, 1.0)
    return pts[j] + f[:, None] * seg[j]


class _Builder:
    """Collects elements in driving order, giving lane runs their ids."""

    def __init__(self) -> None:
        self.rows: list[tuple[float, float, int, int, float]] = []
        self.last_lane: tuple[float, np.ndarray, np.ndarray] | None = None

    def hop(self, s0: float, s1: float) -> None:
        if s1 - s0 > MATCH_TOLERANCE_M:
            self._add(s0, s1, HOP, s1 - s0)

    def drive(self, s0: float, path: np.ndarray, axis: float | None) -> float:
        """Add the elements of a pass driven from arc length ``s0``; its end's arc length."""
        seg = np.diff(path, axis=0)
        seg_len = np.hypot(*seg.T)
        total = float(seg_len.sum())
        if total <= MATCH_TOLERANCE_M:
            return s0
        along = np.zeros(len(seg), dtype=bool)
        if axis is not None:
            unit = np.array([math.cos(axis), math.sin(axis)])
            cos = np.abs(seg @ unit) / np.maximum(seg_len, 1e-18)
            along = cos >= math.cos(math.radians(AXIS_TOLERANCE_DEG))
        if seg_len[along].sum() < LANE_SHARE * total:
            self._add(s0, s0 + total, PASS, 0.0)
            return s0 + total
        s = s0
        for k in range(len(seg)):
            if seg_len[k] <= MATCH_TOLERANCE_M:
                continue
            if along[k]:
                self._lane(s, s + seg_len[k], path[k], path[k + 1])
            elif self.rows and self.rows[-1][2] == TURN and abs(self.rows[-1][1] - s) < 1e-9:
                a, _, kind, run, hop = self.rows[-1]
                self.rows[-1] = (a, s + seg_len[k], kind, run, hop)
            else:
                self._add(s, s + seg_len[k], TURN, 0.0)
            s += seg_len[k]
        return s0 + total

    def _lane(self, s0: float, s1: float, a: np.ndarray, b: np.ndarray) -> None:
        run = len(self.rows)
        last = self.last_lane
        if last is not None and self.rows and self.rows[-1][2] == LANE:
            end_s, la, lb = last
            d0, d1 = lb - la, b - a
            cross = abs(d0[0] * (b - la)[1] - d0[1] * (b - la)[0]) / max(np.hypot(*d0), 1e-18)
            if abs(end_s - s0) < 1e-9 and float(d0 @ d1) > 0 and cross < SAME_LINE_M:
                run = self.rows[-1][3]
        self._add(s0, s1, LANE, 0.0, run)
        self.last_lane = (s1, a, b)

    def _add(self, s0: float, s1: float, kind: int, hop: float, run: int | None = None) -> None:
        self.rows.append((s0, s1, kind, len(self.rows) if run is None else run, hop))

    def result(self) -> TourElements:
        rows = np.array(self.rows, dtype=float).reshape(-1, 5)
        return TourElements(
            start_m=rows[:, 0],
            end_m=rows[:, 1],
            kind=rows[:, 2].astype(np.int64),
            run=rows[:, 3].astype(np.int64),
            hop_m=rows[:, 4],
        )


def plan_elements(plan: CoveragePlan, robot: int = 0) -> TourElements:
    """The elements of robot ``robot``'s path in ``plan``: its sweep tasks in tour order, each
    driven as one of its variants either way, with its room's lane direction."""
    angles = nx.get_node_attributes(plan.room_graph, "angle")
    tasks = plan.tasks[robot]
    return tour_elements(
        plan.paths[robot],
        [[path_of(t, o) for o in range(2 * len(t.variants))] for t in tasks],
        [angles.get(t.room) for t in tasks],
    )
