"""Time map merging: ``python tests/map_merge_timing.py [--repeat N]``.

Two robots' maps are cut from a floor (the home world's grid, and the recorded apartment when
../shared is there), each seeing a little more than its half (3 m seen by both), the second
in a frame turned by 7° and shifted by (0.37, −0.21) m. Prints, per floor, the map sizes, the
best wall-clock and CPU time of merge_maps by the true transforms, refine_transform from a
prior off by 0.3 m and 5°, place_map with no prior and find_frontiers (on the first robot's
map alone, from its most open cell), and the errors of the refined and placed transforms.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from map_pieces import DATA, LIMITS, grid_floor, piece
from robots import ROBOT

from fleet.world import load_ros_map, load_world
from planners.frontiers import find_frontiers
from planners.grid import clearance
from planners.map_match import MatchParams, place_map, refine_transform
from planners.map_merge import Transform2D, merge_maps

B_TO_A = Transform2D(0.37, -0.21, math.radians(7.0))
PARAMS = MatchParams()
SENSOR_RANGE = 6.0  # lidar.range_max


def best_of(repeat: int, f):
    """The fewest milliseconds of wall clock and of process CPU time (the machine may be shared)
    ``f`` took in ``repeat`` calls, as "wall/cpu", and its result."""
    wall, cpu, out = [], [], None
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        out = f()
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return f"{min(wall) * 1e3:.0f}/{min(cpu) * 1e3:.0f}", out


def run(name: str, floor_grid, repeat: int) -> None:
    floor = grid_floor(floor_grid)
    seen = np.argwhere(~floor_grid.unknown)
    (x0, y0), (x1, y1) = (
        floor_grid.cell_to_world(seen.min(axis=0)),
        floor_grid.cell_to_world(seen.max(axis=0)),
    )
    res = floor_grid.resolution
    bounds = (x0 - res, y0 - res, x1 + res, y1 + res)
    mid = (x0 + x1) / 2
    a = piece(floor, lambda xy: xy[..., 0] < mid + 1.5, Transform2D.identity(), bounds, res)
    b = piece(floor, lambda xy: xy[..., 0] > mid - 1.5, B_TO_A, bounds, res)
    ga = a.to_gridmap(PARAMS.occupied_threshold, PARAMS.free_threshold)
    gb = b.to_gridmap(PARAMS.occupied_threshold, PARAMS.free_threshold)
    prior = Transform2D(B_TO_A.x + 0.3, B_TO_A.y, B_TO_A.theta - math.radians(5.0))
    t_merge, merged = best_of(
        repeat, lambda: merge_maps([a, b], [Transform2D.identity(), B_TO_A], LIMITS)
    )
    t_refine, refined = best_of(repeat, lambda: refine_transform(gb, ga, prior, PARAMS))
    t_place, placed = best_of(repeat, lambda: place_map(gb, ga, PARAMS))
    start = ga.cell_to_world(np.unravel_index(np.argmax(clearance(ga)), ga.shape))
    t_front, frontiers = best_of(
        repeat, lambda: find_frontiers(ga, start[None], ROBOT.radius, SENSOR_RANGE)
    )
    for label, m in (("refine", refined), ("place", placed)):
        t = m.transform
        print(
            f"{name}: {label} error ({t.x - B_TO_A.x:+.3f}, {t.y - B_TO_A.y:+.3f}) m, "
            f"{math.degrees(t.theta - B_TO_A.theta):+.2f}°, {m.reason}"
        )
    print(
        f"{name}: maps {a.shape} and {b.shape} cells, merged {merged.shape}; "
        f"ms wall/cpu: merge {t_merge}, refine {t_refine}, place {t_place}, "
        f"frontiers {t_front} ({len(frontiers)} found)"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    home = load_world("configs/worlds/home.yaml").grid(0.05)
    run("home", home, args.repeat)
    apartment = DATA / "cob_ipa_apartment.yaml"
    if apartment.exists():
        run("apartment", load_ros_map(apartment), args.repeat)
    else:
        print(f"apartment: {apartment} is absent, not timed")


if __name__ == "__main__":
    main()
