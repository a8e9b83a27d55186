"""Lanes on one lattice per room, clamp lanes, and targeted fill-in passes."""

import itertools

import numpy as np
from coverage_maps import boxed, furnished, grid_of, open_spots
from robots import ROBOT

from planners.coverage import CoverageParams, plan_coverage
from planners.coverage.bcd import decompose
from planners.coverage.fill_in import chains, fill_points
from planners.coverage.lattice import room_lanes
from planners.coverage.metrics import swath
from planners.coverage.sweeps import lane_rows, lanes_of
from planners.grid import dilate


def _ring_room():
    """A square room around a table: four cells (below, left, right, above the table)."""
    mask = np.zeros((70, 70), dtype=bool)
    mask[5:65, 5:65] = True
    mask[28:41, 20:46] = False
    labels, cells = decompose(mask, max_step=0)
    clean = dilate(mask, 3.0, 1.0)
    return mask, labels, cells, clean


def _sweep_counts(shape, lanes):
    swept = np.zeros(shape, dtype=int)
    for ln in lanes:
        for y, lo, hi in ln:
            rows = np.arange(int(np.ceil(y - 3 + 1e-9)), int(np.floor(y + 3 - 1e-9)) + 1)
            swept[rows[:, None], np.arange(int(lo), int(hi) + 1)[None, :]] += 1
    return swept


def test_cells_around_a_table_share_one_lattice_and_rarely_sweep_the_same_strip():
    mask, labels, cells, clean = _ring_room()
    assert len(cells) == 4
    placed = room_lanes(cells, mask, clean, labels, 6, 3.0)
    lanes = placed.lanes() + list(placed.shoulders)
    for ln in lanes:  # lane centres stay on robot-centre cells
        for y, lo, hi in ln:
            for r in {int(np.floor(y)), int(np.ceil(y))}:
                assert mask[r, int(lo) : int(hi) + 1].all()
    swept = _sweep_counts(mask.shape, lanes)
    assert (swept[mask] >= 1).mean() > 0.97
    # each cell placing its own lanes from its first to its last row sweeps the strips at the
    # table's top and bottom twice; on one lattice only the clamp lanes at walls overlap
    per_cell = [lanes_of(c, lane_rows(c, 6.0)) for c in cells]
    twice_own = int((_sweep_counts(mask.shape, per_cell) > 1).sum())
    twice = int((swept > 1).sum())
    assert twice < 0.6 * twice_own


def test_shoulder_lanes_sweep_the_strip_a_stepped_wall_leaves():
    # one merged cell: a doorway (rows 4–19) under the left half of a room whose floor begins
    # at row 20 on the left and row 23 on the right; no lattice phase fits both steps
    mask = np.zeros((60, 80), dtype=bool)
    mask[4:20, 10:20] = True
    mask[20:55, 5:40] = True
    mask[23:55, 40:76] = True
    labels, cells = decompose(mask, max_step=max(mask.shape))
    assert len(cells) == 1
    clean = dilate(mask, 3.0, 1.0)
    placed = room_lanes(cells, mask, clean, labels, 6, 3.0)
    lanes, shoulders = placed.lanes(), list(placed.shoulders)
    assert len(shoulders[0]) >= 1
    without = (_sweep_counts(mask.shape, lanes)[clean] >= 1).mean()
    with_shoulders = (_sweep_counts(mask.shape, lanes + shoulders)[clean] >= 1).mean()
    assert with_shoulders > without + 0.01
    for y, lo, hi in shoulders[0]:  # shoulder lanes stay on robot-centre cells
        for r in {int(np.floor(y)), int(np.ceil(y))}:
            assert mask[r, int(lo) : int(hi) + 1].all()


def test_fill_points_reach_every_missed_cell_and_lie_on_robot_centres():
    rng = np.random.default_rng(3)
    reach = np.zeros((40, 40), dtype=bool)
    reach[8:32, 8:32] = True
    clean = dilate(reach, 3.0, 1.0)
    covered = clean & (rng.random(clean.shape) < 0.7)
    pts, gain = fill_points(clean, covered, reach, 3.0)
    assert reach[pts[:, 0], pts[:, 1]].all()
    assert gain.sum() == (clean & ~covered).sum()
    hit = covered.copy()
    rr, cc = np.indices(clean.shape)
    for r, c in pts:
        hit |= (rr - r) ** 2 + (cc - c) ** 2 < 9 - 1e-9
    assert (clean & ~hit).sum() == 0
    for group in chains(pts, 6.0):
        assert sorted(group.tolist()) == sorted(set(group.tolist()))


def _crossings(grid, path):
    pts = [path[:1]]
    for a, b in itertools.pairwise(path):
        n = max(2, int(np.ceil(np.hypot(*(b - a)) / (grid.resolution / 4))) + 1)
        pts.append(a + (b - a) * np.linspace(0, 1, n)[:, None])
    rc = grid.world_to_cell(np.vstack(pts))
    return int((grid.occupied | grid.unknown)[rc[:, 0], rc[:, 1]].sum())


def test_fill_in_reaches_the_target_and_its_passes_never_cross_blocked_cells():
    for seed in (4, 5):
        g = furnished(seed)
        starts = open_spots(g, 1)
        without = plan_coverage(g, starts, CoverageParams(fill_in=False), ROBOT, wall_clearance=0.0)
        full = plan_coverage(
            g, starts, CoverageParams(fill_in_target=1.0), ROBOT, wall_clearance=0.0
        )
        assert full.metrics.total.coverage > without.metrics.total.coverage
        assert full.metrics.total.coverage >= 0.999
        assert all(_crossings(g, p) == 0 for p in full.paths)
        # the passes only add to the sweeps: every cleanable cell the sweeps covered stays
        # covered (the transits differ, so the brush may touch other obstacle cells)
        before, _ = swath(g, without.paths[0], 0.15)
        after, _ = swath(g, full.paths[0], 0.15)
        assert not (before & ~after & full.cleanable).any()


def test_fill_in_target_bounds_the_passes():
    g = grid_of(boxed(60, 90))
    start = (1.0, 1.0)
    loose = plan_coverage(g, [start], CoverageParams(fill_in_target=0.9), ROBOT, wall_clearance=0.0)
    tight = plan_coverage(g, [start], CoverageParams(fill_in_target=1.0), ROBOT, wall_clearance=0.0)
    assert tight.metrics.total.coverage == 1.0
    assert loose.metrics.total.path_length_m <= tight.metrics.total.path_length_m


def test_a_wall_strip_beside_a_doorway_is_swept_at_the_coordinators_resolution():
    # at 2.5 cm the living room's last lattice lane leaves a strip along its top wall that is
    # one patch with the doorway's floor above it; the lane for it runs below the doorway
    from pathlib import Path

    from fleet.world import load_world

    w = load_world(Path(__file__).resolve().parents[2] / "configs" / "worlds" / "home.yaml")
    g = w.grid(0.025)
    starts = [p[:2] for p in w.start_poses(1, 0.17)]
    plan = plan_coverage(g, starts, CoverageParams(fill_in=False), ROBOT, wall_clearance=0.0)
    assert plan.metrics.total.coverage >= 0.975


def _cluttered_room(rng, shape=(90, 110)):
    """A room with a stepped wall and a few boxes in it: many cells, many candidate phases."""
    mask = np.zeros(shape, dtype=bool)
    mask[4:-4, 4:-4] = True
    for r in range(4, shape[0] - 4, 7):  # a staircase wall, as a turned wall rasterizes
        mask[r : r + 7, 4 : 4 + int(rng.integers(0, 9))] = False
    for _ in range(4):
        r, c = rng.integers(10, shape[0] - 20), rng.integers(15, shape[1] - 25)
        mask[r : r + rng.integers(4, 14), c : c + rng.integers(4, 18)] = False
    labels, cells = decompose(mask, max_step=max(mask.shape))
    return mask, labels, cells, dilate(mask, 3.0, 1.0)


def test_phases_alike_in_their_decisions_cost_the_same_and_the_first_best_phase_wins():
    # room_lanes evaluates one phase per set of lattice decisions (lattice._decisions): the
    # others must cost exactly what it costs, or it might pass over the cheapest phase
    from planners.coverage import lattice as lat

    rng = np.random.default_rng(3)
    skipped = 0
    for spacing, hw in ((9.9996, 6.0), (6.7, 4.4), (10.8, 6.4)):
        mask, labels, cells, clean = _cluttered_room(rng)
        owner = lat.extend_labels(labels, clean)
        boxes = lat.ndimage.find_objects(owner, max_label=len(cells))
        owned = [
            lat._Owned((b[0].start, b[1].start), clean[b] & (owner[b] == k))
            for k, b in enumerate(boxes, start=1)
        ]
        by_decision: dict = {}
        costs = []
        for phase in lat._phases(cells, spacing):
            lattice = [lat._lattice_lanes(c, mask, phase, spacing) for c in cells]
            placed = lat._lanes_for_phase(cells, lattice, owned, phase, spacing, hw, mask.shape)
            cost = lat._cost(placed.shoulders, lat.TASK_COST_CELLS) + lat._cost(placed.lanes(), 1)
            # all but the lattice lanes' row coordinates, which are the phase's own
            made = (
                cost,
                tuple(ln[:, 1:].tobytes() for ln in placed.lattice),
                tuple(ln.tobytes() for ln in (*placed.clamps, *placed.shoulders)),
            )
            by_decision.setdefault(lat._decisions(lattice, mask.shape, hw), set()).add(made)
            costs.append((cost, phase))
        skipped += len(costs) - len(by_decision)
        assert all(len(m) == 1 for m in by_decision.values())
        best = min(costs, key=lambda cp: cp[0])  # first of the cheapest, as room_lanes takes
        assert room_lanes(cells, mask, clean, labels, spacing, hw).phase == best[1]
    assert skipped > 0  # the dedupe had something to do (at the near-whole spacing)
    # between the same two rows a lane's swath (half-width 4.4 rows) covers rows 6–14 at 10.3
    # and 7–15 at 10.7; a clamp lane below it may take row 5 at 10.3 but row 6 at 10.7
    shape = (40, 40)
    assert lat._decisions([[(10.3, 0, 5)]], shape, 4.4) != lat._decisions(
        [[(10.7, 0, 5)]], shape, 4.4
    )
    assert lat._decisions([[(10.2, 0, 5)]], shape, 4.4) == lat._decisions(
        [[(10.3, 0, 5)]], shape, 4.4
    )
