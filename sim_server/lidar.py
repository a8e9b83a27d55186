"""Simulated 2D lidar: exact ray casting against line segments and discs, vectorized.

Ranges are exact first intersections of each beam (a ray) with the world's static segments
(walls, furniture edges) and the other robots' discs. Instead of testing every beam against
every segment, each primitive is *rasterized onto the beams it subtends*: a segment seen from the
sensor covers the angular interval between its endpoints, a disc the interval
``bearing ± asin(r / d)``. Those intervals are looked up in the sorted beam angles
(``np.searchsorted``), expanded into (beam, primitive) pairs, intersected exactly and reduced
with ``np.minimum.at``. The work is proportional to the number of beams times the depth
complexity of the scene (how many primitives each beam passes), not beams × primitives.
Segments farther than ``range_max`` from the sensor are culled first; for large maps a
:class:`SegmentIndex` (a uniform grid of per-cell candidate lists) makes that cull independent
of the map size. When the segments are the counter-clockwise boundaries of closed polygons and
every sensor is outside them (robots in a vector world), segments seen from their inner side
are culled too (back-face culling): a ray from outside meets a polygon's boundary first where
it enters it, through a face turned towards the sensor, so about half the edges never need a
test.

Ray–segment intersection follows the parametric form of Goldman, "Intersection of two lines in
three-space" (Graphics Gems, 1990), restricted to the plane; ray–circle intersection the
geometric form ``t = (m·d) − sqrt(r² − (m×d)²)``.

:func:`occupancy_to_segments` turns a ROS occupancy grid into the boundary segments of its
occupied cells, so map_server worlds are cast against the same way.
"""

from __future__ import annotations

import functools
import math

import numpy as np

TAU = 2.0 * math.pi
# Beams within this angle of a primitive's angular interval are tested exactly; the exact test
# decides, so the margin only guarantees that rays through an endpoint or corner are never lost.
_ANGLE_MARGIN = 1e-9
# Hits within this distance (m) beyond a segment's endpoint count, so corners shared by two
# segments never leak a ray between them.
_ENDPOINT_SLACK = 1e-9
# |sin| of the angle between ray and segment below which the two are treated as parallel.
_PARALLEL_SIN = 1e-12
# An origin this close (m) to a segment or inside a disc is blocked: range 0 on every beam.
_TOUCH = 1e-9
# Sensors are cast in blocks of about this many rays, so the (ray, primitive) temporaries stay
# a few hundred kB: reused from the heap and in cache, where whole-fleet arrays of many MB are
# mapped fresh from the OS on every call (page faults cost more than the arithmetic).
_RAYS_PER_BLOCK = 4096


def _segment_geometry(segments: np.ndarray) -> tuple[np.ndarray, ...]:
    """(S, 4) segments → start x, start y, unit direction x, y, length; zero-length ones dropped."""
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    ex = seg[:, 2] - seg[:, 0]
    ey = seg[:, 3] - seg[:, 1]
    length = np.hypot(ex, ey)
    keep = length > 0
    length = length[keep]
    return seg[keep, 0], seg[keep, 1], ex[keep] / length, ey[keep] / length, length


class SegmentIndex:
    """A uniform grid over static segments, built once per world, for culling by distance.

    Each cell lists every segment whose distance to the cell centre is at most
    ``reach + cell·√2/2``, so a sensor anywhere in the cell finds all segments within ``reach``
    in that one list (plus a margin the exact cull removes). A sensor outside the grid, which
    spans the segments' bounding box grown by ``reach``, has no segment within reach.
    """

    def __init__(self, segments: np.ndarray, cell: float = 1.0, reach: float = 6.0) -> None:
        if cell <= 0 or reach <= 0:
            raise ValueError("SegmentIndex: cell and reach must be > 0")
        self.cell = float(cell)
        self.reach = float(reach)
        self.ax, self.ay, self.ux, self.uy, self.length = _segment_geometry(segments)
        n = self.length.size
        if n == 0:
            self.lo = np.zeros(2)
            self.shape = (0, 0)
            self.indptr = np.zeros(1, dtype=np.int64)
            self.indices = np.zeros(0, dtype=np.int64)
            return
        bx = self.ax + self.ux * self.length
        by = self.ay + self.uy * self.length
        self.lo = np.array([min(self.ax.min(), bx.min()), min(self.ay.min(), by.min())]) - reach
        hi = np.array([max(self.ax.max(), bx.max()), max(self.ay.max(), by.max())]) + reach
        nx, ny = np.maximum(np.ceil((hi - self.lo) / cell).astype(np.int64), 1)
        self.shape = (int(ny), int(nx))
        cx = self.lo[0] + (np.arange(nx) + 0.5) * cell
        cy = self.lo[1] + (np.arange(ny) + 0.5) * cell
        centres_x = np.tile(cx, ny)
        centres_y = np.repeat(cy, nx)
        limit = reach + cell * math.sqrt(0.5)
        counts = np.empty(centres_x.size, dtype=np.int64)
        chunks = []
        step = max(1, 2_000_000 // n)
        for k in range(0, centres_x.size, step):
            d = _point_segment_distance(
                self.ax - centres_x[k : k + step, None],
                self.ay - centres_y[k : k + step, None],
                self.ux,
                self.uy,
                self.length,
            )
            near = d <= limit
            counts[k : k + step] = near.sum(axis=1)
            chunks.append(np.nonzero(near)[1])
        self.indptr = np.concatenate([[0], np.cumsum(counts)])
        self.indices = np.concatenate(chunks)

    def candidates(self, ox: np.ndarray, oy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Sensor positions → (sensor index, segment index) pairs that may lie within reach."""
        ny, nx = self.shape
        col = np.floor((ox - self.lo[0]) / self.cell).astype(np.int64)
        row = np.floor((oy - self.lo[1]) / self.cell).astype(np.int64)
        inside = (col >= 0) & (col < nx) & (row >= 0) & (row < ny)
        cell = np.where(inside, row * nx + col, 0)
        counts = np.where(inside, self.indptr[cell + 1] - self.indptr[cell], 0)
        total = int(counts.sum())
        sensor = np.repeat(np.arange(ox.size), counts)
        first = self.indptr[cell] - (np.cumsum(counts) - counts)
        return sensor, self.indices[np.arange(total) + np.repeat(first, counts)]


def _point_segment_distance(wx, wy, ux, uy, length):
    """Distance from a point to a segment, given w = start − point and the unit direction."""
    along = np.clip(-(wx * ux + wy * uy), 0.0, length)
    return np.hypot(wx + along * ux, wy + along * uy)


class _Beams:
    """Beam angles sorted once, for finding the beams inside an angular interval."""

    def __init__(self, beam_angles: np.ndarray) -> None:
        rel = np.mod(np.asarray(beam_angles, dtype=np.float64), TAU)
        self.count = rel.size
        self.order = np.argsort(rel, kind="stable")
        s = rel[self.order]
        self.sorted3 = np.concatenate([s - TAU, s, s + TAU])
        self.order3 = np.tile(self.order, 3)
        # Evenly spaced beams over the full circle (the usual scanner) are found by arithmetic,
        # much faster than a binary search.
        self.step = TAU / self.count if self.count else 0.0
        wrap_gap = s[0] + TAU - s[-1] if self.count else 0.0
        self.uniform = self.count > 1 and bool(
            np.all(np.abs(np.diff(s) - self.step) < 1e-9) and abs(wrap_gap - self.step) < 1e-9
        )
        self.first = float(s[0]) if self.count else 0.0

    def expand(
        self, sensor: np.ndarray, start: np.ndarray, extent: np.ndarray, every: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Intervals [start, start + extent] (relative to heading) → (beams per pair, ray index).

        ``every`` marks pairs that must be tested on all beams. Rays are listed pair by pair
        (so per-pair values expand with ``np.repeat(values, counts)``); a ray's index is
        ``sensor · B + beam``.
        """
        b = self.count
        s = np.mod(start, TAU)
        if self.uniform:
            lo = b + np.ceil((s - _ANGLE_MARGIN - self.first) / self.step).astype(np.int64)
            hi = b + 1 + np.floor((s + extent + _ANGLE_MARGIN - self.first) / self.step)
            hi = hi.astype(np.int64)
        else:
            lo = np.searchsorted(self.sorted3, s - _ANGLE_MARGIN, side="left")
            hi = np.searchsorted(self.sorted3, s + extent + _ANGLE_MARGIN, side="right")
        lo = np.where(every, b, lo)
        counts = np.where(every, b, np.minimum(hi - lo, b))
        first = np.cumsum(counts) - counts
        pos = np.arange(int(first[-1] + counts[-1])) + np.repeat(lo - first, counts)
        return counts, self.order3[pos] + np.repeat(sensor * b, counts)


@functools.lru_cache(maxsize=16)
def _beams_cached(angles: bytes) -> _Beams:
    return _Beams(np.frombuffer(angles, dtype=np.float64))


def _cast_segments(
    out, dirs, ox, oy, headings, beams, geom, sensor, seg, range_max, one_sided
) -> None:
    ax, ay, ux, uy, length = geom
    wx = ax[seg] - ox[sensor]
    wy = ay[seg] - oy[sensor]
    ux, uy, length = ux[seg], uy[seg], length[seg]
    dist = _point_segment_distance(wx, wy, ux, uy, length)
    near = dist <= range_max
    if one_sided:
        # w × u < 0: the sensor is on the segment's right, outside its polygon.
        near &= (wx * uy - wy * ux < _TOUCH) | (dist <= _TOUCH)
    keep = np.nonzero(near)[0]
    if keep.size == 0:
        return
    sensor, wx, wy, ux, uy, length = (a[keep] for a in (sensor, wx, wy, ux, uy, length))
    heading = headings[sensor]
    phi_a = np.arctan2(wy, wx) - heading
    phi_b = np.arctan2(wy + uy * length, wx + ux * length) - heading
    sweep = np.mod(phi_b - phi_a + math.pi, TAU) - math.pi
    start = np.where(sweep >= 0, phi_a, phi_b)
    counts, ray = beams.expand(sensor, start, np.abs(sweep), dist[keep] <= _TOUCH)
    # Rows: w (start − origin), unit direction, signed distance of the origin from the line, length.
    p = np.repeat(np.stack([wx, wy, ux, uy, wx * uy - wy * ux, length]), counts, axis=1)
    d = np.take(dirs, ray, axis=1)
    den = d[0] * p[3] - d[1] * p[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = p[4] / den
        along = (p[0] * d[1] - p[1] * d[0]) / den
    hit = (t >= 0) & (along >= -_ENDPOINT_SLACK) & (along <= p[5] + _ENDPOINT_SLACK)
    t = np.where(hit, t, np.inf)
    parallel = np.nonzero(np.abs(den) <= _PARALLEL_SIN)[0]
    if parallel.size:
        t[parallel] = _collinear_hit(p[:, parallel], d[:, parallel])
    np.minimum.at(out, ray, t)


def _collinear_hit(p: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Range along a ray parallel to a segment: its nearest point ahead if on the same line."""
    near = p[0] * d[0] + p[1] * d[1]
    far = near + p[5] * (p[2] * d[0] + p[3] * d[1])
    near, far = np.minimum(near, far), np.maximum(near, far)
    on_line = np.abs(p[4]) <= _TOUCH
    return np.where(on_line & (far >= 0), np.maximum(near, 0.0), np.inf)


def _cast_discs(out, dirs, ox, oy, headings, beams, discs, self_index, range_max) -> None:
    r_count, d_count = ox.size, discs.shape[0]
    mx = (discs[None, :, 0] - ox[:, None]).ravel()
    my = (discs[None, :, 1] - oy[:, None]).ravel()
    rad = np.broadcast_to(discs[:, 2], (r_count, d_count)).ravel()
    sensor = np.repeat(np.arange(r_count), d_count)
    disc = np.broadcast_to(np.arange(d_count), (r_count, d_count)).ravel()
    dist = np.hypot(mx, my)
    keep = np.nonzero((dist - rad <= range_max) & (disc != self_index[sensor]))[0]
    if keep.size == 0:
        return
    sensor, mx, my, rad, dist = (a[keep] for a in (sensor, mx, my, rad, dist))
    inside = dist <= rad + _TOUCH
    half = np.arcsin(np.minimum(rad / np.maximum(dist, _TOUCH), 1.0))
    start = np.arctan2(my, mx) - headings[sensor] - half
    counts, ray = beams.expand(sensor, start, 2.0 * half, inside)
    p = np.repeat(np.stack([mx, my, rad, inside]), counts, axis=1)
    d = np.take(dirs, ray, axis=1)
    along = p[0] * d[0] + p[1] * d[1]
    off = p[0] * d[1] - p[1] * d[0]
    h2 = p[2] * p[2] - off * off
    t = along - np.sqrt(np.maximum(h2, 0.0))
    t = np.where((h2 >= 0) & (t >= 0), t, np.inf)
    t = np.where(p[3] > 0, 0.0, t)
    np.minimum.at(out, ray, t)


def cast_scans(
    origins: np.ndarray,
    headings: np.ndarray,
    beam_angles: np.ndarray,
    segments: np.ndarray | SegmentIndex,
    discs: np.ndarray,
    range_max: float,
    self_index: np.ndarray | None = None,
    one_sided: bool = False,
) -> np.ndarray:
    """Exact lidar ranges for R sensors, each with the same B beams.

    Args:
        origins: (R, 2) sensor positions (m).
        headings: (R,) sensor headings (rad).
        beam_angles: (B,) beam angles relative to the heading (rad), any order.
        segments: (S, 4) static edges ``x1, y1, x2, y2`` (m), or a :class:`SegmentIndex`
            over them (built with ``reach >= range_max``) for large maps.
        discs: (D, 3) dynamic discs ``x, y, radius`` (the robots).
        range_max: beams with nothing within this range read ``inf``.
        self_index: (R,) index in ``discs`` of each sensor's own body, never seen; −1 for none.
        one_sided: the segments are the edges of closed polygons, each polygon counter-clockwise
            (interior on the left of every edge), and no sensor is inside a polygon; edges seen
            from inside are then skipped, with the same result (see :func:`polygon_edges`).

    Returns:
        (R, B) float64 ranges to the first intersection, ``inf`` for no hit within range_max.
        A sensor on a segment or inside another disc is blocked and reads 0 on every beam.
    """
    origins = np.asarray(origins, dtype=np.float64).reshape(-1, 2)
    headings = np.asarray(headings, dtype=np.float64).reshape(-1)
    discs = np.asarray(discs, dtype=np.float64).reshape(-1, 3)
    r_count = origins.shape[0]
    if headings.size != r_count:
        raise ValueError(f"cast_scans: {r_count} origins but {headings.size} headings")
    if self_index is None:
        self_index = np.full(r_count, -1, dtype=np.int64)
    self_index = np.asarray(self_index, dtype=np.int64).reshape(-1)
    if self_index.size != r_count:
        raise ValueError(f"cast_scans: {r_count} origins but {self_index.size} self indices")
    beam_angles = np.ascontiguousarray(beam_angles, dtype=np.float64).reshape(-1)
    beams = _beams_cached(beam_angles.tobytes())
    b_count = beams.count
    out = np.full(r_count * b_count, np.inf)
    if r_count == 0 or b_count == 0:
        return out.reshape(r_count, b_count)
    if isinstance(segments, SegmentIndex):
        if segments.reach < range_max:
            raise ValueError(
                f"cast_scans: SegmentIndex reach {segments.reach} < range_max {range_max}"
            )
        geom = (segments.ax, segments.ay, segments.ux, segments.uy, segments.length)
    else:
        geom = _segment_geometry(segments)
    bc, bs = np.cos(beam_angles), np.sin(beam_angles)
    chunk = max(1, _RAYS_PER_BLOCK // b_count)
    for lo in range(0, r_count, chunk):
        hi = min(lo + chunk, r_count)
        ox, oy, heading = origins[lo:hi, 0], origins[lo:hi, 1], headings[lo:hi]
        hc, hs = np.cos(heading)[:, None], np.sin(heading)[:, None]
        dirs = np.stack([(hc * bc - hs * bs).ravel(), (hs * bc + hc * bs).ravel()])
        block = out[lo * b_count : hi * b_count]
        if isinstance(segments, SegmentIndex):
            sensor, seg = segments.candidates(ox, oy)
        else:
            sensor = np.repeat(np.arange(hi - lo), geom[0].size)
            seg = np.broadcast_to(np.arange(geom[0].size), (hi - lo, geom[0].size)).ravel()
        if seg.size:
            _cast_segments(
                block, dirs, ox, oy, heading, beams, geom, sensor, seg, range_max, one_sided
            )
        if discs.shape[0]:
            _cast_discs(block, dirs, ox, oy, heading, beams, discs, self_index[lo:hi], range_max)
    out[out > range_max] = np.inf
    return out.reshape(r_count, b_count)


def polygon_edges(polygons: list[np.ndarray] | tuple[np.ndarray, ...]) -> np.ndarray:
    """(S, 4) edges of closed polygons ((K, 2) vertices each), every polygon counter-clockwise,
    as :func:`cast_scans` with ``one_sided=True`` needs them."""
    edges = []
    for poly in polygons:
        poly = np.asarray(poly, dtype=np.float64)
        x, y = poly[:, 0], poly[:, 1]
        if np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)) < 0:  # shoelace: clockwise
            poly = poly[::-1]
        edges.append(np.hstack([poly, np.roll(poly, -1, axis=0)]))
    return np.vstack(edges) if edges else np.zeros((0, 4))


def add_noise(
    ranges: np.ndarray,
    sigma: float,
    range_min: float,
    range_max: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """Gaussian range noise of std ``sigma``; readings beyond ``range_max`` (no return) →
    ``inf``, below ``range_min`` (too near to measure) → ``-inf``, as REP 117 has it: a beam
    that saw nothing is evidence of free space, one too near is not.

    As a real scanner, the validity check applies to the measured (noisy) value: a true range
    just inside range_max may read beyond it and report no return. Nothing else is clipped.
    """
    ranges = np.asarray(ranges, dtype=np.float64)
    noisy = ranges + sigma * rng.standard_normal(ranges.shape)
    noisy = np.where(np.isfinite(noisy) & (noisy > range_max), np.inf, noisy)
    return np.where(noisy < range_min, -np.inf, noisy)


def _runs(edges: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Maximal runs of True along each row of a 2D boolean array → (row, first, end) arrays."""
    padded = np.zeros((edges.shape[0], edges.shape[1] + 2), dtype=np.int8)
    padded[:, 1:-1] = edges
    step = np.diff(padded, axis=1)
    row, first = np.nonzero(step == 1)
    _, end = np.nonzero(step == -1)
    return row, first, end


def occupancy_to_segments(
    occupied: np.ndarray, resolution: float, origin: tuple[float, float]
) -> np.ndarray:
    """Boundary of the occupied cells of a grid as (S, 4) segments ``x1, y1, x2, y2``.

    Conventions of ROS ``nav_msgs/OccupancyGrid`` (as ``planners.grid``): row 0 is the lowest y,
    cell ``(r, c)`` spans ``x ∈ [ox + c·res, ox + (c+1)·res)`` and y likewise. Every cell edge
    between an occupied cell and a non-occupied one (or the outside of the grid) is boundary;
    collinear neighbouring edges are merged into maximal horizontal and vertical runs.
    """
    occ = np.asarray(occupied, dtype=bool)
    if occ.ndim != 2:
        raise ValueError("occupancy_to_segments: occupied must be a 2D array")
    ox, oy = float(origin[0]), float(origin[1])
    res = float(resolution)
    padded = np.zeros((occ.shape[0] + 2, occ.shape[1] + 2), dtype=bool)
    padded[1:-1, 1:-1] = occ
    # Horizontal edge line i lies at y = oy + i·res, between rows i−1 and i.
    horizontal = padded[1:, 1:-1] != padded[:-1, 1:-1]
    line, first, end = _runs(horizontal)
    y = oy + line * res
    h = np.stack([ox + first * res, y, ox + end * res, y], axis=1)
    # Vertical edge line j lies at x = ox + j·res, between columns j−1 and j.
    vertical = padded[1:-1, 1:] != padded[1:-1, :-1]
    line, first, end = _runs(vertical.T)
    x = ox + line * res
    v = np.stack([x, oy + first * res, x, oy + end * res], axis=1)
    return np.concatenate([h, v]).astype(np.float64)


def cast_scans_reference(
    origins: np.ndarray,
    headings: np.ndarray,
    beam_angles: np.ndarray,
    segments: np.ndarray,
    discs: np.ndarray,
    range_max: float,
    self_index: np.ndarray | None = None,
) -> np.ndarray:
    """Brute-force :func:`cast_scans`: every beam against every segment and disc, per sensor.

    O(R·B·(S + D)) with no culling and no angular lookup; the oracle for tests and the baseline
    of ``fleet bench lidar``. Same arguments and result, except that it ignores the degenerate
    cases (a beam running exactly along a segment, a sensor on a segment).
    """
    origins = np.asarray(origins, dtype=np.float64).reshape(-1, 2)
    headings = np.asarray(headings, dtype=np.float64).reshape(-1)
    discs = np.asarray(discs, dtype=np.float64).reshape(-1, 3)
    beam_angles = np.asarray(beam_angles, dtype=np.float64)
    ax, ay, ux, uy, length = _segment_geometry(segments)
    if self_index is None:
        self_index = np.full(origins.shape[0], -1)
    out = np.full((origins.shape[0], beam_angles.size), np.inf)
    for i, ((px, py), heading) in enumerate(zip(origins, headings, strict=True)):
        angles = heading + beam_angles
        dx, dy = np.cos(angles)[:, None], np.sin(angles)[:, None]
        wx, wy = ax - px, ay - py
        den = dx * uy - dy * ux
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (wx * uy - wy * ux) / den
            along = (wx * dy - wy * dx) / den
        hit = (t >= 0) & (along >= -_ENDPOINT_SLACK) & (along <= length + _ENDPOINT_SLACK)
        t = np.where(hit & (np.abs(den) > _PARALLEL_SIN), t, np.inf)
        ranges = t.min(axis=1, initial=np.inf)
        others = np.arange(discs.shape[0]) != self_index[i]
        mx, my, rad = discs[others, 0] - px, discs[others, 1] - py, discs[others, 2]
        along = mx * dx + my * dy
        h2 = rad**2 - (mx * dy - my * dx) ** 2
        t = along - np.sqrt(np.maximum(h2, 0.0))
        t = np.where((h2 >= 0) & (t >= 0), t, np.inf)
        t = np.where(np.hypot(mx, my) <= rad, 0.0, t)
        out[i] = np.minimum(ranges, t.min(axis=1, initial=np.inf))
    out[out > range_max] = np.inf
    return out
