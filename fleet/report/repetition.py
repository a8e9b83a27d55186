"""Where a run's repetition comes from: every re-entry of a cell under the brush, charged to what
the robot was doing and to the element of the tour it was driving.

Repetition (report.json) counts every time a cleanable cell enters a brush after the first. This
module replays each robot's true track (``tracks.csv``) over the run's cleaning grid
(``coverage.npz``) with the simulator's own brush (``sim_server.cleaning.CleaningGrid``), takes
each cell's entries in time order, and charges every entry but the first to:

* the **step kind** in force (``fleet.protocol.TIME_KINDS``): the kind whose seconds grew most
  between the two statuses of the robot around that moment (``status.csv``);
* the **tour element** driven: the robot's plan at that moment (``status.csv``'s plan id, the
  plan from ``plans.jsonl``), the stretch of it the robot was on (its true position projected
  onto the segments between the waypoints it headed for in the statuses around that moment),
  and what that stretch is in the coordinator's one-robot tour (its elements from the job's
  store, ``planners.tour_elements``): a lane, a turn inside a lane group, another pass (fill-in,
  strips), a hop between passes (by its length), the transit to the plan's first task, a
  detour round a lost robot's body (a sweep that is not on the tour), or no plan at all. A
  position more than half a swath from its plan is *off the planned path*.

The headline **cause** of a re-entry is the first of:

* its step kind, when that is one of ``KIND_CAUSES`` (turning in place, escaping, giving way,
  holding, idle);
* a lane over its own line: the entry before it in the cell came from the same lane (tracking
  wobble, or the lane driven again);
* **passes side by side**: the cell lies between the line of this move and the line of the move
  that swept it last, on opposite sides of it, at least ``SIDE_SHARE`` of the brush width from
  each: where neighbouring passes of the tour overlap, two lanes (**lane overlap**) or a hop
  (or another pass) beside a lane or a hop;
* for a lane, what swept the cell last: a turn or a hop ≤ ``SHORT_HOP_M`` (**lane ends**: the
  U-turn's floor), a longer hop, a transit, another lane not beside it (a crossing lane, or a
  drift onto the neighbour's floor), or anything else (a pass, an escape, a detour);
* else the element itself (hops by length, turns, passes, transits, ...).

Causes are in points of repetition (re-entries / swept cells × 100) and sum to the replay's
repetition. The track keeps every position the simulator moved the brush to (1.25 cm steps,
at the rate it cleans), so the replay counts what the simulator counted
(``cells_as_simulated``: the share of cleanable cells with the simulator's visit count;
``replay_gap``: the simulator's repetition less the replay's, 0 unless truth messages were
dropped).

The same breakdown of the tour alone (no follower, no peers: the coordinator's one-robot tour
swept on the same grid) is the planned part.
"""

from __future__ import annotations

import json
import re
import sqlite3
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fleet.protocol import TIME_KINDS
from fleet.report.summary import (
    PLANS_FILE,
    REPORT_FORMAT,
    STATUS_COLUMNS,
    STATUS_FILE,
    ReportError,
    RunData,
    load_run,
    read_csv,
)
from planners.grid import GridMap
from planners.tour_elements import HOP, LANE, PASS, TURN, TourElements, locate
from sim_server.cleaning import CleaningGrid

STATE_FILE = "coordinator.sqlite"
# hops are split by length: U-turns between lane pieces, short hops, long ones
SHORT_HOP_M = 0.35
LONG_HOP_M = 1.0
# moves are replayed in pieces no longer than this (exact: the brush model is exact for any
# straight move; shorter pieces only keep the brush's window of cells small)
PIECE_M = 0.25
# brush moves swept per call, to bound memory
CHUNK = 4096
# a re-entered cell between two moves at least this share of the brush width from each lies
# where passes side by side overlap (passes 0.3 m apart or less for a 0.3 m brush)
SIDE_SHARE = 0.25
# a waypoint window wider than this (statuses far apart) is searched at its far end only
MAX_WINDOW = 512
# where a path runs over itself, the segment the statuses' waypoints put the robot on at that
# moment (interpolated in time) wins: this much distance per segment away from it
TIE_M = 1e-3

# element classes of a moment of a run (or of the tour)
ELEMENTS = (
    "lane",
    "turn",
    "pass",
    "hop_long",
    "hop_mid",
    "hop_short",
    "transit",
    "detour",
    "off_path",
    "no_plan",
)
E_LANE, E_TURN, E_PASS, E_HOP_LONG, E_HOP_MID, E_HOP_SHORT, E_TRANSIT, E_DETOUR, E_OFF, E_NONE = (
    range(len(ELEMENTS))
)
# step kinds of the robots' statuses, and "unknown" where no status says
KINDS = (*TIME_KINDS, "unknown")
UNKNOWN_KIND = len(TIME_KINDS)
KIND_CAUSES = {
    "turn": "turn_in_place",
    "escape": "escape",
    "yield": "give_way",
    "hold": "hold",
    "idle": "idle",
}
# the headline causes, in the order the tables show them
CAUSES = (
    "lanes_side_by_side",
    "hop_side_by_side",
    "lane_ends",
    "lane_over_hop",
    "lane_over_transit",
    "lane_over_lane",
    "lane_over_other",
    "lane_own",
    "turn",
    "pass",
    "hop_long",
    "hop_mid",
    "hop_short",
    "transit",
    "detour",
    "off_path",
    "no_plan",
    "turn_in_place",
    "escape",
    "give_way",
    "hold",
    "idle",
)
CAUSE_LABELS = {
    "lanes_side_by_side": "lanes side by side (lane overlap)",
    "hop_side_by_side": "a hop or pass side by side with a lane or hop",
    "lane_ends": "lane over its U-turn's floor (lane ends)",
    "lane_over_hop": f"lane over floor a hop > {SHORT_HOP_M:g} m swept",
    "lane_over_transit": "lane over floor a transit swept",
    "lane_over_lane": "lane over another lane's floor, not beside it",
    "lane_over_other": "lane over floor a pass, escape or detour swept",
    "lane_own": "lane over its own line (wobble, driven again)",
    "turn": "turns inside lane groups",
    "pass": "other passes (fill-in, strips)",
    "hop_long": f"hops > {LONG_HOP_M:g} m",
    "hop_mid": f"hops {SHORT_HOP_M:g}-{LONG_HOP_M:g} m",
    "hop_short": f"hops <= {SHORT_HOP_M:g} m (U-turns)",
    "transit": "transits to a plan's first task",
    "detour": "detours round a body",
    "off_path": "off the planned path",
    "no_plan": "no plan",
    "turn_in_place": "turning in place",
    "escape": "escapes",
    "give_way": "giving way",
    "hold": "holding for a peer",
    "idle": "idle (stepping aside)",
}

# the causes by what would remove them: the tour's hops, its lanes' spacing and tracking, its
# U-turns, the transits between tasks, its other passes, and the follower and its peers
GROUPS = {
    "hops": ("hop_long", "hop_mid", "hop_side_by_side", "lane_over_hop"),
    "lanes_over_lanes": ("lanes_side_by_side", "lane_over_lane", "lane_own"),
    "u_turns": ("hop_short", "lane_ends", "turn"),
    "transits": ("transit", "lane_over_transit"),
    "passes": ("pass", "lane_over_other"),
    "execution": (
        "off_path",
        "turn_in_place",
        "escape",
        "give_way",
        "hold",
        "idle",
        "no_plan",
        "detour",
    ),
}
GROUP_LABELS = {
    "hops": "the tour's hops (> 0.35 m), with the floor lanes sweep after them",
    "lanes_over_lanes": "lanes over lanes (side by side, drifted onto, crossing)",
    "u_turns": "U-turns and lane ends",
    "transits": "transits between tasks, with the floor lanes sweep after them",
    "passes": "fill-in and other passes",
    "execution": "the follower and its peers (turns in place, escapes, giving way, off path)",
}


@dataclass(frozen=True, eq=False)
class Moves:
    """Brush moves in the order they happened: ``start``/``end`` (M, 2) world points, ``fresh``
    (M,) a brush that was not on the floor before, ``time`` (M,) when (sim s, or arc length
    for a tour), ``element`` (M,) class (``ELEMENTS``), ``run`` (M,) the lane run for lanes
    (else -1), ``kind`` (M,) step kind (``KINDS``)."""

    start: np.ndarray
    end: np.ndarray
    fresh: np.ndarray
    time: np.ndarray
    element: np.ndarray
    run: np.ndarray
    kind: np.ndarray


@dataclass(frozen=True, eq=False)
class Tour:
    """The coordinator's one-robot tour: its path, elements and own figures."""

    path: np.ndarray
    elements: TourElements
    figures: dict[str, Any]


@dataclass(frozen=True, eq=False)
class PlanMap:
    """One plan as sent, each segment (waypoint j to j + 1) mapped to the tour: ``element``
    (E_TRANSIT before the sweep, E_DETOUR where the sweep is not on the tour, else -1: look
    the element up at the segment's arc length), ``s0`` the tour's arc length at the
    segment's start and ``sign`` +1 / -1 as the plan drives the tour forwards or backwards."""

    waypoints: np.ndarray
    element: np.ndarray
    s0: np.ndarray
    sign: np.ndarray


# ---- reading a run dir ----------------------------------------------------------------------


def _missing(path: Path, report: dict[str, Any]) -> ReportError:
    return ReportError(
        f"{path} does not exist: `fleet up` writes it since report format {REPORT_FORMAT} "
        f"(report.json field format); this run's report.json has format "
        f"{report.get('format', 1)}"
    )


def read_status(path: Path, report: dict[str, Any]) -> dict[str, np.ndarray]:
    """Per robot, its statuses as rows (sim_s, plan_id, waypoint, seconds per TIME_KIND),
    sorted by time."""
    if not path.exists():
        raise _missing(path, report)
    rows: dict[str, list[list[float]]] = {}
    for line, row in read_csv(path, STATUS_COLUMNS):
        try:
            values = [float(row[k]) for k in STATUS_COLUMNS if k != "robot"]
        except ValueError:
            raise ReportError(f"{path}:{line}: a field is not a number: {row}") from None
        if not np.all(np.isfinite(values)):
            raise ReportError(f"{path}:{line}: a field is not finite: {row}")
        rows.setdefault(row["robot"], []).append(values)
    out = {}
    for rid, r in rows.items():
        a = np.array(r, dtype=float)
        out[rid] = a[np.argsort(a[:, 0], kind="stable")]
    return out


def read_plans(path: Path, report: dict[str, Any]) -> dict[tuple[str, int], dict[str, Any]]:
    """Every plan sent, by (robot, plan id): the first version (a plan cut short later keeps
    the same id and a prefix of its waypoints)."""
    if not path.exists():
        raise _missing(path, report)
    plans: dict[tuple[str, int], dict[str, Any]] = {}
    for line, text in enumerate(path.read_text().splitlines(), start=1):
        if not text.strip():
            continue
        try:
            p = json.loads(text)
            key = (str(p["robot"]), int(p["plan_id"]))
            p["waypoints"] = np.asarray(p["waypoints"], dtype=float).reshape(-1, 2)
            p["sweep_from"] = int(p["sweep_from"])
            p["chain_starts"] = [int(v) for v in p["chain_starts"]]
        except json.JSONDecodeError as e:
            raise ReportError(f"{path}:{line}: not JSON: {e}") from None
        except KeyError as e:
            raise ReportError(f"{path}:{line}: missing field {e.args[0]}") from None
        except (TypeError, ValueError) as e:
            raise ReportError(f"{path}:{line}: a field has the wrong type: {e}") from None
        plans.setdefault(key, p)
    return plans


def read_tour(path: Path) -> Tour:
    """The coordinator's tour from its store: the original tasks' paths in order, joined, and
    the elements it labelled when it planned."""
    if not path.exists():
        raise ReportError(f"{path} does not exist: `fleet up` writes the coordinator's job there")
    try:
        db = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
        try:
            meta = dict(db.execute("SELECT key, value FROM meta").fetchall())
            # the tour's own tasks: not their remainders, nor an exploring job's frontiers
            rows = db.execute(
                "SELECT id, path FROM tasks WHERE parent IS NULL AND kind = 'tour'"
            ).fetchall()
        finally:
            db.close()
    except sqlite3.Error as e:
        raise ReportError(f"{path}: not a readable job store: {e}") from None
    if "tour_elements" not in meta:
        raise ReportError(
            f"{path}: no field tour_elements in its meta: the coordinator writes it since "
            f"report format {REPORT_FORMAT} (report.json field format)"
        )
    try:
        raw = json.loads(meta["tour_elements"])
        figures = json.loads(meta.get("tour", "null")) or {}
    except json.JSONDecodeError as e:
        raise ReportError(f"{path}: meta tour_elements or tour is not JSON: {e}") from None
    if raw is None:
        raise ReportError(f"{path}: tour_elements is null: the coordinator could not label it")
    try:
        elements = TourElements.from_json(raw)
    except ValueError as e:
        raise ReportError(f"{path}: meta tour_elements: {e}") from None
    order = []
    for tid, blob in rows:
        m = re.fullmatch(r"[A-Za-z]*(\d+)", tid)
        if m is None:
            raise ReportError(f"{path}: task {tid!r} has no parent and no tour index")
        order.append((int(m.group(1)), np.frombuffer(blob, dtype="<f8").reshape(-1, 2)))
    if not order:
        raise ReportError(f"{path}: no tasks")
    order.sort(key=lambda r: r[0])
    parts = [order[0][1]] + [p[1:] for _, p in order[1:]]
    tour = np.vstack(parts)
    length = float(np.hypot(*np.diff(tour, axis=0).T).sum())
    if len(elements) and abs(length - float(elements.end_m[-1])) > 1e-3:
        raise ReportError(
            f"{path}: the tasks make a tour of {length:.3f} m but tour_elements end at "
            f"{elements.end_m[-1]:.3f} m: they are not one plan"
        )
    return Tour(tour, elements, figures)


# ---- labelling moves ------------------------------------------------------------------------


def element_class(elements: TourElements, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(class, lane run) of the tour at arc lengths ``s`` (runs -1 but for lanes)."""
    i = elements.at(s)
    kind = np.where(i >= 0, elements.kind[np.clip(i, 0, None)], -1)
    hop = elements.hop_m[np.clip(i, 0, None)]
    cls = np.full(len(s), E_NONE, dtype=np.int64)
    cls[kind == LANE] = E_LANE
    cls[kind == TURN] = E_TURN
    cls[kind == PASS] = E_PASS
    is_hop = kind == HOP
    cls[is_hop & (hop > LONG_HOP_M)] = E_HOP_LONG
    cls[is_hop & (hop > SHORT_HOP_M) & (hop <= LONG_HOP_M)] = E_HOP_MID
    cls[is_hop & (hop <= SHORT_HOP_M)] = E_HOP_SHORT
    run = np.where(kind == LANE, elements.run[np.clip(i, 0, None)], -1)
    return cls, run


def map_plan(plan: dict[str, Any], tour: np.ndarray) -> PlanMap:
    """Each segment of ``plan`` against the tour: the transit, then each chained task's sweep
    found on the tour (forwards or backwards), or a detour where it is not on it."""
    wp = plan["waypoints"]
    n = max(len(wp) - 1, 0)
    element = np.full(n, E_DETOUR, dtype=np.int64)
    s0 = np.full(n, np.nan)
    sign = np.ones(n)
    sweep_from = min(max(plan["sweep_from"], 0), n)
    element[:sweep_from] = E_TRANSIT
    starts = sorted({sweep_from, *[c for c in plan["chain_starts"] if sweep_from <= c < n]})
    for a, b in zip(starts, [*starts[1:], n], strict=True):
        piece = wp[a : b + 1]
        if len(piece) < 2:
            continue
        arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(piece, axis=0).T))])
        at = locate(tour, piece)
        if at is not None:
            s0[a:b] = at + arc[:-1]
            element[a:b] = -1
            continue
        at = locate(tour, piece[::-1])
        if at is not None:
            s0[a:b] = at + arc[-1] - arc[:-1]
            sign[a:b] = -1.0
            element[a:b] = -1
    return PlanMap(wp, element, s0, sign)


def dominant_kinds(status: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The step kind at each time of ``t``: the kind whose seconds grew most between the two
    statuses around it (after the last status, or with none: unknown)."""
    if len(status) == 0:
        return np.full(len(t), UNKNOWN_KIND, dtype=np.int64)
    cum = status[:, 3:]
    grown = np.diff(np.vstack([np.zeros((1, cum.shape[1])), cum]), axis=0)
    # an agent started again counts from zero
    grown = np.where((grown < 0).any(axis=1, keepdims=True), cum, grown)
    k = np.searchsorted(status[:, 0], t, side="left")
    out = np.argmax(grown[np.clip(k, 0, len(status) - 1)], axis=1)
    quiet = grown[np.clip(k, 0, len(status) - 1)].max(axis=1) <= 0
    return np.where((k >= len(status)) | quiet, UNKNOWN_KIND, out)


def label_track(
    times: np.ndarray,
    xy: np.ndarray,
    status: np.ndarray,
    plans: dict[int, PlanMap],
    elements: TourElements,
    half_swath: float,
) -> tuple[np.ndarray, np.ndarray]:
    """(class, lane run) of a robot at each of its track points: the plan its statuses name
    around that time, the segment of it nearest the point among those between the waypoints
    they headed for, and that segment's element."""
    n = len(times)
    cls = np.full(n, E_NONE, dtype=np.int64)
    run = np.full(n, -1, dtype=np.int64)
    if len(status) == 0 or n == 0:
        return cls, run
    k = np.clip(np.searchsorted(status[:, 0], times, side="left"), 0, len(status) - 1)
    plan_id = status[k, 1].astype(np.int64)
    before = np.maximum(k - 1, 0)
    same = (status[before, 1].astype(np.int64) == plan_id) & (k > 0)
    lo = np.where(same, status[before, 2], 0).astype(np.int64) - 1
    hi = status[k, 2].astype(np.int64) - 1
    span = np.maximum(status[k, 0] - status[before, 0], 1e-9)
    share = np.clip((times - status[before, 0]) / span, 0.0, 1.0)
    expected = np.where(same, lo + share * (hi - lo), hi)
    for pid in np.unique(plan_id):
        plan = plans.get(int(pid))
        rows = np.nonzero(plan_id == pid)[0]
        if plan is None or len(plan.element) == 0:
            continue
        last = len(plan.element) - 1
        a = np.clip(lo[rows], 0, last)
        b = np.clip(np.maximum(hi[rows], a), 0, last)
        width = min(int((b - a).max()) + 1, MAX_WINDOW)
        a = np.maximum(a, b - width + 1)
        seg = np.minimum(a[:, None] + np.arange(width)[None, :], b[:, None])
        j, f, gap = _nearest_segment(plan.waypoints, seg, xy[rows], expected[rows])
        c = plan.element[j].copy()
        seg_len = np.hypot(*(plan.waypoints[j + 1] - plan.waypoints[j]).T)
        s = plan.s0[j] + plan.sign[j] * f * seg_len
        on_tour = c < 0
        tc, tr = element_class(elements, s[on_tour])
        c[on_tour] = tc
        r = np.full(len(rows), -1, dtype=np.int64)
        r[on_tour] = tr
        c[gap > half_swath] = E_OFF
        cls[rows], run[rows] = c, r
    return cls, run


def _nearest_segment(
    wp: np.ndarray, seg: np.ndarray, xy: np.ndarray, expected: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each point of ``xy`` ((n, 2)) the nearest of its candidate segments ``seg`` ((n, w)
    indices into the waypoints ``wp``), ties going to the one nearest ``expected`` (n,):
    (index, fraction along it, distance)."""
    a, b = wp[seg], wp[seg + 1]
    d = b - a
    rel = xy[:, None, :] - a
    f = np.clip(
        np.einsum("nwk,nwk->nw", rel, d) / np.maximum(np.einsum("nwk,nwk->nw", d, d), 1e-18),
        0.0,
        1.0,
    )
    gap = np.hypot(*(rel - f[..., None] * d).transpose(2, 0, 1))
    best = np.argmin(gap + TIE_M * np.abs(seg - expected[:, None]), axis=1)
    rows = np.arange(len(xy))
    return seg[rows, best], f[rows, best], gap[rows, best]


def track_moves(
    data: RunData,
    status: dict[str, np.ndarray],
    plans: dict[tuple[str, int], dict[str, Any]],
    tour: Tour,
) -> Moves:
    """Every robot's track as brush moves, each labelled by the robot's step kind and element
    at its end."""
    parts = []
    half = data.cleaning_width_m / 2
    maps: dict[tuple[str, int], PlanMap] = {k: map_plan(p, tour.path) for k, p in plans.items()}
    for rid, tr in sorted(data.tracks.items()):
        if len(tr) == 0:
            continue
        st = status.get(rid, np.zeros((0, 3 + len(TIME_KINDS))))
        mine = {pid: m for (r, pid), m in maps.items() if r == rid}
        xy = tr[:, 1:3]
        cls, run = label_track(tr[:, 0], xy, st, mine, tour.elements, half)
        kind = dominant_kinds(st, tr[:, 0])
        start = np.vstack([xy[:1], xy[:-1]])
        fresh = np.zeros(len(tr), dtype=bool)
        fresh[0] = True
        parts.append(Moves(start, xy, fresh, tr[:, 0], cls, run, kind))
    return _split(_concat(parts))


def tour_moves(tour: Tour) -> Moves:
    """The tour as brush moves from its start, cut at its elements' ends, each labelled by
    its element (time: arc length)."""
    pts = tour.path
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    cuts = np.union1d(arc, np.clip(tour.elements.end_m, 0.0, arc[-1]))
    j = np.clip(np.searchsorted(arc, cuts, side="right") - 1, 0, len(pts) - 2)
    f = (cuts - arc[j]) / np.maximum(arc[j + 1] - arc[j], 1e-18)
    at = pts[j] + np.clip(f, 0.0, 1.0)[:, None] * (pts[j + 1] - pts[j])
    start = np.vstack([at[:1], at[:-1]])
    mid = 0.5 * (np.concatenate([cuts[:1], cuts[:-1]]) + cuts)
    cls, run = element_class(tour.elements, mid)
    fresh = np.zeros(len(at), dtype=bool)
    fresh[0] = True
    kind = np.full(len(at), UNKNOWN_KIND, dtype=np.int64)
    return _split(Moves(start, at, fresh, cuts, cls, run, kind))


def _concat(parts: Sequence[Moves]) -> Moves:
    if not parts:
        z = np.zeros((0, 2))
        e = np.zeros(0, dtype=np.int64)
        return Moves(z, z, np.zeros(0, dtype=bool), np.zeros(0), e, e, e)
    return Moves(
        *(
            np.concatenate([getattr(p, f) for p in parts])
            for f in ("start", "end", "fresh", "time", "element", "run", "kind")
        )
    )


def _split(m: Moves) -> Moves:
    """The moves cut into pieces of at most ``PIECE_M``, each keeping its move's labels."""
    length = np.hypot(*(m.end - m.start).T)
    n = np.maximum(1, np.ceil(length / PIECE_M)).astype(np.int64)
    i = np.repeat(np.arange(len(n)), n)
    k = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    d = m.end[i] - m.start[i]
    f0, f1 = (k / n[i])[:, None], ((k + 1) / n[i])[:, None]
    return Moves(
        m.start[i] + f0 * d,
        m.start[i] + f1 * d,
        m.fresh[i] & (k == 0),
        m.time[i],
        m.element[i],
        m.run[i],
        m.kind[i],
    )


# ---- charging re-entries --------------------------------------------------------------------


def charge(moves: Moves, grid: GridMap, cleanable: np.ndarray, width: float) -> dict[str, Any]:
    """Sweep ``moves`` with the simulator's brush (``width`` wide) over ``grid`` and charge
    every re-entry of a cleanable cell: the counts by cause, kind and element (and kind ×
    element), the swept cells and the visits per cell."""
    brush = CleaningGrid(grid, cleanable, width)
    cells, moved = [], []
    for a in range(0, len(moves.time), CHUNK):
        b = min(a + CHUNK, len(moves.time))
        c, m = brush.swept_by(moves.start[a:b], moves.end[a:b], moves.fresh[a:b])
        cells.append(c)
        moved.append(m + a)
    cell = np.concatenate(cells) if cells else np.zeros(0, dtype=np.int64)
    move = np.concatenate(moved) if moved else np.zeros(0, dtype=np.int64)
    keep = cleanable.reshape(-1)[cell]
    cell, move = cell[keep], move[keep]
    order = np.lexsort((move, moves.time[move], cell))
    cell, move = cell[order], move[order]
    again = np.concatenate([[False], cell[1:] == cell[:-1]])
    prev = np.concatenate([[0], move[:-1]])
    centre = grid.cell_to_world(np.stack(np.divmod(cell, cleanable.shape[1]), axis=1))
    beside = side_by_side(moves, move, prev, centre, width)
    el, kind = moves.element[move], moves.kind[move]
    cause = _causes(el, kind, moves.element[prev], moves.run[move], moves.run[prev], beside)
    swept = int(np.count_nonzero(~again))
    visits = np.bincount(cell, minlength=cleanable.size).reshape(cleanable.shape)
    return {
        "swept_cells": swept,
        "re_entries": int(again.sum()),
        "cause": np.bincount(cause[again], minlength=len(CAUSES)),
        "kind": np.bincount(kind[again], minlength=len(KINDS)),
        "element": np.bincount(el[again], minlength=len(ELEMENTS)),
        "kind_element": np.bincount(
            kind[again] * len(ELEMENTS) + el[again], minlength=len(KINDS) * len(ELEMENTS)
        ).reshape(len(KINDS), len(ELEMENTS)),
        "visits": visits,
    }


def side_by_side(
    moves: Moves, now: np.ndarray, before: np.ndarray, xy: np.ndarray, width: float
) -> np.ndarray:
    """Whether each cell centre of ``xy`` lies where two passes side by side overlap: between
    the lines of moves ``now`` and ``before`` (on opposite sides of them, their feet from it
    at least 135° apart), at least ``SIDE_SHARE`` of the brush width from each."""
    foot_now, gap_now = _to_line(moves, now, xy)
    foot_before, gap_before = _to_line(moves, before, xy)
    least = SIDE_SHARE * width
    apart = np.einsum("ij,ij->i", foot_now, foot_before) < -np.sqrt(0.5) * gap_now * gap_before
    return (gap_now >= least) & (gap_before >= least) & apart


def _to_line(moves: Moves, index: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """From each point of ``xy`` to the line of move ``index`` (to its start, where the move
    has no length): the vector to the nearest point, and its length."""
    a, b = moves.start[index], moves.end[index]
    d = b - a
    length2 = np.einsum("ij,ij->i", d, d)
    rel = a - xy
    along = np.where(
        length2 > 1e-18, -np.einsum("ij,ij->i", rel, d) / np.maximum(length2, 1e-18), 0.0
    )
    foot = rel + along[:, None] * d
    return foot, np.hypot(*foot.T)


def _causes(
    el: np.ndarray,
    kind: np.ndarray,
    prev_el: np.ndarray,
    run: np.ndarray,
    prev_run: np.ndarray,
    beside: np.ndarray,
) -> np.ndarray:
    """The headline cause (index into ``CAUSES``) of each entry, from its element and kind,
    the element and lane run of the entry before it in the same cell, and whether the cell
    lies where the two moves overlap side by side. First match wins: the step kinds of
    ``KIND_CAUSES``; a lane over its own line; passes side by side; then the element (a lane
    by what swept the cell before it)."""
    index = {c: i for i, c in enumerate(CAUSES)}
    by_element = np.array(
        [
            index["lane_over_other"],
            index["turn"],
            index["pass"],
            index["hop_long"],
            index["hop_mid"],
            index["hop_short"],
            index["transit"],
            index["detour"],
            index["off_path"],
            index["no_plan"],
        ]
    )
    # a lane by what swept the cell before it
    after = np.full(len(ELEMENTS), index["lane_over_other"])
    after[[E_TURN, E_HOP_SHORT]] = index["lane_ends"]
    after[[E_HOP_MID, E_HOP_LONG]] = index["lane_over_hop"]
    after[E_TRANSIT] = index["lane_over_transit"]
    after[E_LANE] = index["lane_over_lane"]
    lane = el == E_LANE
    cause = np.where(lane, after[prev_el], by_element[el])
    beside &= (el < E_TRANSIT) & (prev_el < E_TRANSIT)
    cause[beside] = index["hop_side_by_side"]
    cause[beside & lane & (prev_el == E_LANE)] = index["lanes_side_by_side"]
    cause[lane & (prev_el == E_LANE) & (prev_run == run) & (run >= 0)] = index["lane_own"]
    for name, c in KIND_CAUSES.items():
        cause[kind == TIME_KINDS.index(name)] = index[c]
    return cause


# ---- one run --------------------------------------------------------------------------------


def _points(counts: np.ndarray, names: Sequence[str], swept: int) -> dict[str, float]:
    return {
        n: round(100.0 * float(c) / max(swept, 1), 3) for n, c in zip(names, counts, strict=True)
    }


def grouped(causes: dict[str, float]) -> dict[str, float]:
    """Points of repetition by ``GROUPS``: what would remove them."""
    return {g: round(sum(causes[c] for c in members), 3) for g, members in GROUPS.items()}


def breakdown(run_dir: Path, subdivide: int = 1) -> dict[str, Any]:
    """The repetition breakdown of one run dir written by ``fleet up`` (see the module
    docstring); ReportError naming the file and field when something it needs is missing.

    With ``subdivide`` N > 1 the replay runs on the run's grid with every cell cut into N × N
    (cleanable as the cell it lies in): how the figures move when the floor is counted finer
    than the simulator counts it (its 5 cm cells see lanes 0.25 m apart under a 0.30 m brush
    overlap by one row of cells or by none, as the lanes fall on them); ``cells_as_simulated``
    is then None."""
    if subdivide < 1:
        raise ValueError(f"subdivide must be >= 1, got {subdivide}")
    data = load_run(run_dir)
    report = data.report
    status = read_status(run_dir / STATUS_FILE, report)
    plans = read_plans(run_dir / PLANS_FILE, report)
    tour = read_tour(run_dir / STATE_FILE)
    cleanable = np.kron(data.cleanable, np.ones((subdivide, subdivide), dtype=bool))
    grid = GridMap(
        np.zeros(cleanable.shape, dtype=bool),
        np.zeros(cleanable.shape, dtype=bool),
        data.resolution / subdivide,
        data.origin,
    )
    width = data.cleaning_width_m
    live = charge(track_moves(data, status, plans, tour), grid, cleanable, width)
    planned = charge(tour_moves(tour), grid, cleanable, width)
    swept = live["swept_cells"]
    total = int(cleanable.sum())
    replay = 100.0 * live["re_entries"] / max(swept, 1)
    same = None
    if subdivide == 1:
        sim_visits = data.visits * data.cleanable
        agree = np.count_nonzero((live["visits"] == sim_visits) & data.cleanable)
        same = round(agree / max(total, 1), 4)
    return {
        "run_dir": str(run_dir),
        "world": Path(str(report.get("world", ""))).stem,
        "seed": report.get("seed"),
        "robots": len(data.tracks),
        "cell_m": grid.resolution,
        "repetition": round(100.0 * float(report["repetition"]), 3),
        "replay_repetition": round(replay, 3),
        "replay_gap": round(100.0 * float(report["repetition"]) - replay, 3),
        "replay_coverage": round(swept / max(total, 1), 5),
        "cells_as_simulated": same,
        "causes": (causes := _points(live["cause"], CAUSES, swept)),
        "groups": grouped(causes),
        "kinds": _points(live["kind"], KINDS, swept),
        "elements": _points(live["element"], ELEMENTS, swept),
        "kind_element": {
            k: _points(row, ELEMENTS, swept)
            for k, row in zip(KINDS, live["kind_element"], strict=True)
            if row.any()
        },
        "tour": {
            "repetition": round(100.0 * planned["re_entries"] / max(planned["swept_cells"], 1), 3),
            "coverage": round(planned["swept_cells"] / max(total, 1), 5),
            "causes": (alone := _points(planned["cause"], CAUSES, planned["swept_cells"])),
            "groups": grouped(alone),
            "own": tour.figures,
        },
    }
