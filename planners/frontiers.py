"""Frontiers of an occupancy grid: the places where exploring reveals the unknown.

A frontier cell is a known-free cell 8-adjacent to an unknown one, and 8-connected frontier
cells form a frontier (Yamauchi, "A frontier-based approach for autonomous exploration", CIRA
1997). As there, a frontier smaller than the robot (fewer cells than its diameter over the
resolution) is dropped. A frontier must also be one a robot can drive to: its goal is a
frontier cell whose centre keeps the robot's radius from every occupied cell and that is
4-connected through such cells to a robot (unknown cells do not block: the robot drives up to
the unknown, as in Yamauchi).

Its expected information gain is the unknown area a sensor of ``sensor_range`` at the goal would
see, counting unknown cells as transparent and occupied ones as opaque (the expected visible
area of Burgard et al., "Coordinated multi-robot exploration", IEEE T-RO 21(3), 2005, §III).
:func:`discounted_utility` is their coordination rule: a goal's utility falls by
P(d) = 1 − d / sensor_range (0 beyond the range) for each goal at distance d already assigned to
another robot (their eq. 5).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from planners.grid import GridMap

EIGHT = np.ones((3, 3), dtype=bool)


@dataclass(frozen=True, eq=False)
class Frontier:
    """One frontier: its cells ((K, 2) row, col), size (m: K cells × resolution), centroid and
    goal (world x, y; the goal is the reachable frontier cell nearest the centroid) and the
    expected information gain at the goal (m² of unknown floor in view)."""

    cells: np.ndarray
    size: float
    centroid: tuple[float, float]
    goal: tuple[float, float]
    information_gain: float


def frontier_cells(grid: GridMap) -> np.ndarray:
    """Known-free cells with an unknown cell among their 8 neighbours (outside the grid is
    unknown)."""
    unknown = np.pad(grid.unknown, 1, constant_values=True)
    return grid.free & ndimage.binary_dilation(unknown, structure=EIGHT)[1:-1, 1:-1]


def _safe(grid: GridMap, robot_radius: float) -> np.ndarray:
    """Known-free cells whose centre keeps ``robot_radius`` from every occupied cell's edge."""
    dist = ndimage.distance_transform_edt(~grid.occupied)
    return grid.free & ((dist - 0.5) * grid.resolution >= robot_radius)


def _starts(
    grid: GridMap, safe: np.ndarray, robots: np.ndarray, robot_radius: float
) -> tuple[np.ndarray, np.ndarray]:
    """Per robot ((N, 2) world x, y): whether a safe cell lies within its radius (a pose
    estimate a little off), and the nearest safe cell ((N, 2) row, col; valid where it does)."""
    robots = np.asarray(robots, dtype=float).reshape(-1, 2)
    near = np.zeros((len(robots), 2), dtype=np.int64)
    if not safe.any() or not len(robots):
        return np.zeros(len(robots), dtype=bool), near
    away, (near_r, near_c) = ndimage.distance_transform_edt(~safe, return_indices=True)
    rc = grid.world_to_cell(robots)
    inside = grid.in_bounds(rc)
    r, c = np.where(inside, rc[:, 0], 0), np.where(inside, rc[:, 1], 0)
    close = inside & (away[r, c] * grid.resolution <= robot_radius)
    return close, np.stack([near_r[r, c], near_c[r, c]], axis=-1)


def placed(grid: GridMap, robots: np.ndarray, robot_radius: float) -> np.ndarray:
    """(N,) whether each robot ((N, 2) world x, y) stands on floor of ``grid`` a robot centre
    can be on (within its radius of such a cell). A robot whose own surroundings are not yet
    mapped free reaches no frontier, which does not mean none is left."""
    return _starts(grid, _safe(grid, robot_radius), robots, robot_radius)[0]


def centre_reachable(grid: GridMap, robots: np.ndarray, robot_radius: float) -> np.ndarray:
    """Known-free cells whose centre keeps ``robot_radius`` from every occupied cell's edge,
    4-connected through such cells to a robot ((N, 2) world x, y). A robot standing within its
    radius of such a cell (a pose estimate a little off) starts from the nearest one."""
    safe = _safe(grid, robot_radius)
    close, near = _starts(grid, safe, robots, robot_radius)
    if not close.any():
        return np.zeros_like(safe)
    labels, _ = ndimage.label(safe)
    ids = np.unique(labels[near[close, 0], near[close, 1]])
    return np.isin(labels, ids[ids > 0])


def information_gain(grid: GridMap, goals: np.ndarray, sensor_range: float) -> np.ndarray:
    """(N,) m² of unknown area in view of each of ``goals`` ((N, 2) world x, y).

    Rays every resolution/range radians (one cell apart at full range), sampled every cell;
    a ray stops at its first occupied cell, and each unknown sample (outside the grid counts as
    unknown) adds its polar area element r·dr·dφ. All rays of a goal are cast at once (a few
    hundred thousand samples); goals go one after the other to bound the memory."""
    goals = np.atleast_2d(np.asarray(goals, dtype=float))
    res = grid.resolution
    n_beams = math.ceil(2.0 * math.pi * sensor_range / res)
    dphi = 2.0 * math.pi / n_beams
    radii = (np.arange(math.ceil(sensor_range / res)) + 0.5) * res
    phi = np.arange(n_beams) * dphi
    ray = np.stack([np.cos(phi)[:, None] * radii, np.sin(phi)[:, None] * radii], axis=-1)
    gains = np.empty(len(goals))
    for i, goal in enumerate(goals):
        rc = grid.world_to_cell(goal + ray)
        inside = grid.in_bounds(rc)
        r, c = np.where(inside, rc[..., 0], 0), np.where(inside, rc[..., 1], 0)
        occupied = inside & grid.occupied[r, c]
        unknown = ~inside | grid.unknown[r, c]
        open_ray = ~np.maximum.accumulate(occupied, axis=1)
        gains[i] = float(((unknown & open_ray) * radii).sum() * res * dphi)
    return gains


def find_frontiers(
    grid: GridMap,
    robots: np.ndarray,
    robot_radius: float,
    sensor_range: float,
    reach: np.ndarray | None = None,
) -> tuple[Frontier, ...]:
    """The frontiers of ``grid`` that a robot at one of ``robots`` ((N, 2) world x, y) can
    reach, at least the robot's diameter long, largest information gain first. ``reach``:
    :func:`centre_reachable` of the same, when the caller has it already."""
    cells = frontier_cells(grid)
    labels, n = ndimage.label(cells, structure=EIGHT)
    if n == 0:
        return ()
    if reach is None:
        reach = centre_reachable(grid, robots, robot_radius)
    reach = reach & cells
    rc = np.argwhere(cells)
    lab = labels[rc[:, 0], rc[:, 1]]
    counts = np.bincount(lab, minlength=n + 1)
    mean_r = np.bincount(lab, weights=rc[:, 0], minlength=n + 1) / np.maximum(counts, 1)
    mean_c = np.bincount(lab, weights=rc[:, 1], minlength=n + 1) / np.maximum(counts, 1)
    # the goal: per label, the reachable cell nearest the centroid
    ok = reach[rc[:, 0], rc[:, 1]]
    cand, cand_lab = rc[ok], lab[ok]
    d2 = (cand[:, 0] - mean_r[cand_lab]) ** 2 + (cand[:, 1] - mean_c[cand_lab]) ** 2
    order = np.lexsort((d2, cand_lab))
    first = np.unique(cand_lab[order], return_index=True)
    goal_of = dict(zip(first[0].tolist(), cand[order][first[1]].tolist(), strict=True))
    long_enough = counts >= 2.0 * robot_radius / grid.resolution
    keep = [k for k in goal_of if long_enough[k]]
    if not keep:
        return ()
    goals = grid.cell_to_world(np.array([goal_of[k] for k in keep]))
    centroids = grid.cell_to_world(np.stack([mean_r[keep], mean_c[keep]], axis=-1))
    gains = information_gain(grid, goals, sensor_range)
    by_label = np.argsort(lab, kind="stable")
    groups = np.split(rc[by_label], np.cumsum(counts[1:])[:-1])
    frontiers = [
        Frontier(
            cells=groups[k - 1],
            size=float(counts[k] * grid.resolution),
            centroid=(float(cx), float(cy)),
            goal=(float(gx), float(gy)),
            information_gain=float(gain),
        )
        for k, (cx, cy), (gx, gy), gain in zip(keep, centroids, goals, gains, strict=True)
    ]
    return tuple(sorted(frontiers, key=lambda f: -f.information_gain))


def discounted_utility(
    utility: np.ndarray, goals: np.ndarray, assigned: np.ndarray, sensor_range: float
) -> np.ndarray:
    """Burgard et al. 2005, eq. 5: the utility of each of ``goals`` ((N, 2)) once other robots
    are headed to ``assigned`` ((M, 2)), U · max(0, 1 − Σ P(‖goal − assigned_i‖)) with
    P(d) = max(0, 1 − d / sensor_range), the chance that what a robot at the assigned goal sees
    covers the area seen from this one. With U = 1 (their initial utility) this is their
    U − Σ P, floored at 0; an information gain as U scales it."""
    utility = np.asarray(utility, dtype=float)
    goals = np.atleast_2d(np.asarray(goals, dtype=float))
    assigned = np.asarray(assigned, dtype=float).reshape(-1, 2)
    if assigned.size == 0:
        return utility.copy()
    d = np.linalg.norm(goals[:, None, :] - assigned[None, :, :], axis=-1)
    overlap = np.clip(1.0 - d / sensor_range, 0.0, None).sum(axis=1)
    return utility * np.clip(1.0 - overlap, 0.0, None)
