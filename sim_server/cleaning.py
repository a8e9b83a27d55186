"""Ground-truth cleaning: which floor cells each robot's brush has swept, and how often.

The floor is a grid of ``cell_size`` cells. A robot's brush is a disc of diameter
``cleaning_width`` centred on the robot, so moving straight it sweeps a band of that width; a
cell is under the brush when its centre lies strictly inside the disc, the footprint rule of
``planners.grid.disc``.
A cell's visit count goes up by one each time it *enters* a robot's brush (it was not under that
brush a moment before), so a robot standing still does not inflate the counts and a pass over a
cell counts once however slowly it is made.

Between two updates a robot is taken to have moved along the straight segment joining its two
positions, and its brush swept the whole capsule around that segment (the Minkowski sum of the
segment and the brush disc): a cell enters the brush when its centre lies strictly within the
brush radius of the segment but was not within it of the segment's start. This is exact for a
straight move: a point's distance to a point moving along a line is convex in time, so a cell is
under the brush during one interval of the move and enters it at most once. It equals sampling
the brush at every point of the path, so updates can be sparse (the simulator makes them at
10 Hz, when a robot has moved at most a few centimetres along a nearly straight arc).

A robot with a side brush (``planners.robot.SideBrush``) also sweeps the disc of its bristles,
which moves with the robot's pose; its move between two updates is taken along the chord too
(the bristles' centre turns on an arc of about 0.15 m radius, whose chord is off it by a fraction
of a millimetre at the update rate). The side brush does not count visits: it sweeps dust into
the main brush's path and is what reaches the band along walls the body keeps the main brush
from, so a cell it has touched counts as swept, but repetition stays the main brush's (how much
of the driving goes over floor the robot has already cleaned).

The reference is the **cleanable area**: cells whose centre a robot centre can reach from the
start poses (clearance ≥ robot radius from occupied or unknown cells, connected to a start),
dilated by the main brush, with or without a side brush. Coverage = cleanable cells swept by
either brush / cleanable cells; repetition = (main brush visits summed over the cells it swept)
/ (those cells) − 1.
"""

from __future__ import annotations

import functools

import numpy as np

from planners.grid import GridMap, cleanable, inflate, reachable
from planners.robot import SideBrush


def cleanable_mask(
    grid: GridMap, starts_xy: np.ndarray, robot_radius: float, cleaning_width: float
) -> np.ndarray:
    """The reference area, as the planners define it (``planners.grid``): robot-centre cells
    with clearance ≥ ``robot_radius`` connected to a start, grown by the brush disc."""
    free_centres = ~inflate(grid, robot_radius)
    cells = grid.world_to_cell(np.atleast_2d(starts_xy))
    cells = cells[grid.in_bounds(cells)]
    cells = cells[free_centres[cells[:, 0], cells[:, 1]]]
    if len(cells) == 0:
        return np.zeros(grid.shape, dtype=bool)
    return cleanable(grid, reachable(free_centres, cells), cleaning_width / 2)


@functools.lru_cache(maxsize=8)
def _window(half: int) -> np.ndarray:
    """(row, col) offsets of the (2·half + 1)² cells around a cell."""
    return np.stack(np.mgrid[-half : half + 1, -half : half + 1], axis=-1).reshape(-1, 2)


class CleaningGrid:
    """Visit counts of every floor cell under the main brush, and the cells a side brush has
    touched (``side``), updated from the robots' true poses.

    The cleanable cells swept and their visits summed are counted as cells are swept, so
    :meth:`coverage` and :meth:`repetition` cost nothing however large the floor.
    """

    def __init__(
        self,
        grid: GridMap,
        cleanable: np.ndarray,
        cleaning_width: float,
        side_brush: SideBrush | None = None,
    ) -> None:
        self.grid = grid
        self.cleanable = cleanable
        self.visits = np.zeros(grid.shape, dtype=np.uint16)
        self.radius = cleaning_width / 2
        self.side_brush = side_brush if side_brush is not None and side_brush.enabled else None
        self.side = np.zeros(grid.shape, dtype=bool)
        self._pos: dict[str, tuple[float, float, float]] = {}
        self._cleanable_cells = int(cleanable.sum())
        self._swept_cells = 0
        self._main_swept = 0
        self._visits_sum = 0

    def swept(self, start: np.ndarray, end: np.ndarray, fresh: np.ndarray) -> np.ndarray:
        """Flat indices of the cells that enter the brush as it moves from ``start`` to ``end``.

        ``start`` and ``end`` are (M, 2) positions of M brushes, ``fresh`` (M,) marks brushes that
        were not on the floor at ``start`` (all their cells enter). An index appears once per
        brush it enters, so one cell may appear several times.
        """
        return self.swept_by(start, end, fresh)[0]

    def swept_by(
        self, start: np.ndarray, end: np.ndarray, fresh: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`swept`'s cells, and beside each the index (0 … M − 1) of the brush whose move
        it entered (the run report charges each entry to what that brush was doing)."""
        return self._entered(start, end, fresh, self.radius)

    def _entered(
        self, start: np.ndarray, end: np.ndarray, fresh: np.ndarray, radius: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`swept_by` for discs of ``radius`` moving from ``start`` to ``end``."""
        g = self.grid
        start = np.asarray(start, dtype=np.float64).reshape(-1, 2)
        end = np.asarray(end, dtype=np.float64).reshape(-1, 2)
        seg = end - start
        length2 = np.einsum("ij,ij->i", seg, seg)
        half = int(np.ceil((radius + 0.5 * np.sqrt(length2.max())) / g.resolution)) + 1
        rc = g.world_to_cell(0.5 * (start + end))[:, None, :] + _window(half)[None]
        rel = g.cell_to_world(rc) - start[:, None, :]
        with np.errstate(divide="ignore", invalid="ignore"):
            along = np.einsum("mwk,mk->mw", rel, seg) / length2[:, None]
        along = np.clip(np.nan_to_num(along, nan=0.0), 0.0, 1.0)
        to_path = rel - along[..., None] * seg[:, None, :]
        inner = radius - 1e-9
        in_capsule = np.einsum("mwk,mwk->mw", to_path, to_path) < inner * inner
        at_start = np.einsum("mwk,mwk->mw", rel, rel) < inner * inner
        entered = in_capsule & (np.asarray(fresh, dtype=bool)[:, None] | ~at_start)
        entered &= g.in_bounds(rc)
        return rc[entered, 0] * g.shape[1] + rc[entered, 1], np.nonzero(entered)[0]

    def update(self, robots: list[str], poses: np.ndarray) -> None:
        """Sweep each robot's brushes from its previous update to ``poses`` ((N, 3) x, y,
        theta, one per robot; (N, 2) positions do for a robot without a side brush).

        A robot seen for the first time cleans its footprint. A robot that has moved less than
        a quarter cell (L1) and turned less than a quarter cell at the side brush's reach since
        its previous update is left where it was, so physics jitter does not count cells at
        the brush's rim again and again.
        """
        poses = np.asarray(poses, dtype=np.float64)
        if poses.shape[-1] == 2:
            if self.side_brush is not None:
                raise ValueError("a side brush needs the robots' headings: pass (N, 3) poses")
            poses = np.column_stack([poses.reshape(-1, 2), np.zeros(len(poses.reshape(-1, 2)))])
        poses = poses.reshape(-1, 3)
        nan3 = (np.nan, np.nan, np.nan)
        prev = np.array([self._pos.get(r, nan3) for r in robots]).reshape(-1, 3)
        fresh = np.isnan(prev[:, 0])
        prev = np.where(fresh[:, None], poses, prev)
        step = np.abs(poses[:, :2] - prev[:, :2]).sum(axis=1)
        if self.side_brush is not None:
            turn = np.abs(np.angle(np.exp(1j * (poses[:, 2] - prev[:, 2]))))
            step = np.maximum(step, turn * self.side_brush.reach)
        moved = fresh | (step >= self.grid.resolution / 4)
        idx = np.nonzero(moved)[0]
        if idx.size == 0:
            return
        for i, pose in zip(idx.tolist(), poses[idx].tolist(), strict=True):
            self._pos[robots[i]] = (pose[0], pose[1], pose[2])
        cells = self.swept(prev[idx, :2], poses[idx, :2], fresh[idx])
        visits = self.visits.reshape(-1)
        cleanable = self.cleanable.reshape(-1)
        clean = cells[cleanable[cells]]
        first = np.unique(clean)
        new_main = first[visits[first] == 0]
        self._main_swept += len(new_main)
        self._swept_cells += int(np.count_nonzero(~self.side.reshape(-1)[new_main]))
        self._visits_sum += len(clean)
        np.add.at(visits, cells, 1)
        if self.side_brush is not None:
            self._sweep_side(self.side_brush, prev[idx], poses[idx], fresh[idx])

    def _sweep_side(
        self, brush: SideBrush, prev: np.ndarray, poses: np.ndarray, fresh: np.ndarray
    ) -> None:
        """Mark the cells the side brush's bristles enter moving from ``prev`` to ``poses``."""
        start, end = brush.centres(prev), brush.centres(poses)
        cells = np.unique(self._entered(start, end, fresh, brush.radius)[0])
        side = self.side.reshape(-1)
        new = cells[~side[cells]]
        new_clean = new[self.cleanable.reshape(-1)[new]]
        self._swept_cells += int(np.count_nonzero(self.visits.reshape(-1)[new_clean] == 0))
        side[new] = True

    def forget(self, robot: str) -> None:
        """A robot left; its next appearance starts a fresh pass."""
        self._pos.pop(robot, None)

    @property
    def cleanable_m2(self) -> float:
        return float(self._cleanable_cells) * self.grid.resolution**2

    def swept_mask(self) -> np.ndarray:
        """The cells either brush has swept (cleanable or not)."""
        return (self.visits > 0) | self.side

    def coverage(self) -> float:
        """Cleanable cells swept by either brush / cleanable cells."""
        total = self._cleanable_cells
        return float(self._swept_cells) / total if total else 0.0

    def repetition(self) -> float:
        """Main brush visits summed over the cleanable cells it swept / those cells − 1."""
        swept = self._main_swept
        return float(self._visits_sum) / swept - 1.0 if swept else 0.0
