"""The job as the coordinator keeps it: tasks, their owners and swept pieces, and the robots.

Pure state with the transitions the market makes (no bus, no clock of its own), so every rule
is unit-tested without processes:

- A task is ``open`` (no live owner), ``assigned`` (in one robot's queue, at ``position``),
  ``done``, or ``replaced`` (by its remainder, when its owner was lost part-way).
- A robot drives the first task of its queue; the rest are unstarted, and the back half of them
  may be withdrawn and auctioned again at a task boundary (``withdraw_unstarted``), which is
  how an idle robot wins work back from busy ones.
- A lost robot keeps nothing: the unswept remainder of the task it was driving becomes a new
  open task (``t07`` → ``t07.1``), its unstarted tasks open again (``lose``). No task is ever in
  two queues.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from planners.auction import Task, ahead_of, remainder
from planners.coverage.params import CoverageParams

OPEN, ASSIGNED, DONE, REPLACED = "open", "assigned", "done", "replaced"
ALIVE, LOST, REJOINED = "alive", "lost", "rejoined"


@dataclass
class TaskRecord:
    task: Task
    state: str = OPEN
    owner: str | None = None
    position: int = 0
    reverse: bool = False
    parent: str | None = None
    swept: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))

    def __post_init__(self) -> None:
        if len(self.swept) != self.task.pieces:
            self.swept = np.zeros(self.task.pieces, dtype=bool)

    @property
    def started(self) -> bool:
        return bool(self.swept.any())


@dataclass
class RobotRecord:
    id: str
    liveness: str = ALIVE
    ready: bool = False
    state: str = ""
    task: str = ""
    progress: float = 0.0
    heartbeat_wall: float = 0.0
    restarts: int = 0
    award_seq: int = 0
    acked_seq: int = 0
    xy: tuple[float, float] | None = None

    @property
    def in_market(self) -> bool:
        return self.liveness != LOST and self.ready and self.xy is not None


class Job:
    """Tasks and robots; every method returns what changed so the shell can persist and tell."""

    def __init__(self, params: CoverageParams) -> None:
        self.params = params
        self.tasks: dict[str, TaskRecord] = {}
        self.robots: dict[str, RobotRecord] = {}

    # ---- queries ------------------------------------------------------------------------

    def robot(self, rid: str) -> RobotRecord:
        return self.robots.setdefault(rid, RobotRecord(rid))

    def open_tasks(self) -> list[TaskRecord]:
        return [r for r in self.tasks.values() if r.state == OPEN]

    def queue(self, rid: str) -> list[TaskRecord]:
        """The robot's won tasks in driving order; the first is the one it drives."""
        mine = [r for r in self.tasks.values() if r.state == ASSIGNED and r.owner == rid]
        return sorted(mine, key=lambda r: r.position)

    def current(self, rid: str) -> TaskRecord | None:
        q = self.queue(rid)
        return q[0] if q else None

    def counts(self) -> dict[str, int]:
        out = {OPEN: 0, ASSIGNED: 0, DONE: 0}
        for r in self.tasks.values():
            if r.state in out:
                out[r.state] += 1
        return out

    @property
    def finished(self) -> bool:
        return bool(self.tasks) and all(r.state in (DONE, REPLACED) for r in self.tasks.values())

    def market(self) -> list[str]:
        """Robots that may bid: not lost, localized, with a known pose."""
        return sorted(rid for rid, r in self.robots.items() if r.in_market)

    # ---- transitions --------------------------------------------------------------------

    def add_tasks(self, tasks: tuple[Task, ...]) -> None:
        for t in tasks:
            self.tasks[t.id] = TaskRecord(t)

    def award(self, task_id: str, rid: str, reverse: bool) -> TaskRecord:
        rec = self.tasks[task_id]
        if rec.state != OPEN:
            raise ValueError(f"task {task_id} is {rec.state}, not open")
        if self.robot(rid).liveness == LOST:
            raise ValueError(f"{rid} is lost")
        q = self.queue(rid)
        rec.state, rec.owner, rec.reverse = ASSIGNED, rid, reverse
        rec.position = q[-1].position + 1 if q else 0
        return rec

    def progress(self, rid: str, task_id: str, swept_driven: np.ndarray) -> bool:
        """Merge the pieces ``rid`` reports swept, in the order it drives them; True if new."""
        rec = self.tasks.get(task_id)
        if rec is None or rec.state != ASSIGNED or rec.owner != rid:
            return False
        swept = np.asarray(swept_driven, dtype=bool)
        if len(swept) != rec.task.pieces:
            return False
        if rec.reverse:
            swept = swept[::-1]
        new = swept & ~rec.swept
        rec.swept = rec.swept | swept
        return bool(new.any())

    def finish(self, rid: str, task_id: str) -> bool:
        rec = self.tasks.get(task_id)
        if rec is None or rec.state != ASSIGNED or rec.owner != rid:
            return False
        rec.state = DONE
        rec.swept = np.ones(rec.task.pieces, dtype=bool)
        return True

    def lose(self, rid: str) -> tuple[list[str], list[str]]:
        """``rid`` is lost: (tasks opened again, remainder tasks made). Idempotent."""
        robot = self.robot(rid)
        robot.liveness = LOST
        robot.ready = False
        reopened: list[str] = []
        made: list[str] = []
        for i, rec in enumerate(self.queue(rid)):
            if rec.started:
                new_id = self._next_id(rec.task.id)
                if i == 0 and robot.xy is not None:
                    # its body stays where it stopped: no robot centre comes within two radii
                    clearance = 2 * self.params.robot_radius
                    rest = ahead_of(
                        rec.task, np.array(robot.xy), rec.reverse, clearance, new_id, self.params
                    )
                else:
                    rest = remainder(rec.task, rec.swept, new_id, self.params)
                rec.state, rec.owner = REPLACED, None
                if rest is not None:
                    self.tasks[rest.id] = TaskRecord(rest, parent=rec.task.id)
                    made.append(rest.id)
                    reopened.append(rest.id)
            else:
                rec.state, rec.owner, rec.reverse = OPEN, None, False
                reopened.append(rec.task.id)
        return reopened, made

    def give_back(self, rid: str, task_id: str) -> str | None:
        """``rid``'s plan ended with pieces of ``task_id`` unswept (waypoints it gave up, often
        because a peer stood in the way for a while): a task of the tour goes back to the market
        once, as the remainder of its unswept pieces (as a lost robot's work does), and that
        remainder's id is returned; a task that is already a remainder is not, and None says the
        owner is done with it."""
        rec = self.tasks.get(task_id)
        if rec is None or rec.state != ASSIGNED or rec.owner != rid or rec.parent is not None:
            return None
        rest = remainder(rec.task, rec.swept, self._next_id(task_id), self.params)
        if rest is None:
            return None
        rec.state, rec.owner = REPLACED, None
        self.tasks[rest.id] = TaskRecord(rest, parent=task_id)
        return rest.id

    def withdraw_unstarted(self) -> list[str]:
        """The back half of each robot's unstarted queue (never the task it drives) goes back
        to the market, as in work stealing from the far end of a queue: a robot that wins it
        starts where the owner would have got last, so the two do not work side by side (and
        give way to each other) while they share what is left."""
        out = []
        for rid in sorted({r.owner for r in self.tasks.values() if r.state == ASSIGNED}):
            unstarted = [rec for rec in self.queue(rid)[1:] if not rec.started]  # type: ignore[arg-type]
            for rec in unstarted[len(unstarted) // 2 :]:
                rec.state, rec.owner, rec.reverse = OPEN, None, False
                out.append(rec.task.id)
        return out

    def _next_id(self, task_id: str) -> str:
        base, _, n = task_id.partition(".")
        k = int(n) + 1 if n.isdigit() else 1
        while f"{base}.{k}" in self.tasks:
            k += 1
        return f"{base}.{k}"


@dataclass
class GivenUpWaypoints:
    """Waypoints the robots gave up as unreachable, counted from their status reports.

    An agent reports how many waypoints of the plan it drives it has given up (its count
    starts again with each plan, and may start again when a plan is cut), so every rise of a
    (robot, plan) count is added to the robot's total. ``seen`` is kept with the totals across
    the coordinator's restart, so the counts the agents report again are not added twice.
    """

    by_robot: dict[str, int] = field(default_factory=dict)
    seen: dict[str, int] = field(default_factory=dict)

    def report(self, robot: str, plan_id: int, skipped: int) -> int:
        """Take a robot's status count for a plan; returns how many more it gave up."""
        key = f"{robot}/{plan_id}"
        more = max(0, skipped - self.seen.get(key, 0))
        self.seen[key] = skipped
        if more:
            self.by_robot[robot] = self.by_robot.get(robot, 0) + more
        return more

    @property
    def total(self) -> int:
        return sum(self.by_robot.values())

    def finished_message(self) -> str:
        """What the coordinator says when every task is done."""
        if not self.total:
            return "every task is done, no waypoint given up"
        each = ", ".join(f"{rid} {n}" for rid, n in sorted(self.by_robot.items()) if n)
        return (
            f"every task is done, but {self.total} waypoint(s) were given up as unreachable "
            f"({each}): the floor around them may not be clean"
        )

    def to_json(self) -> dict[str, dict[str, int]]:
        return {"by_robot": dict(self.by_robot), "seen": dict(self.seen)}

    @classmethod
    def from_json(cls, data: object) -> GivenUpWaypoints:
        if not isinstance(data, dict):
            return cls()
        return cls(dict(data.get("by_robot", {})), dict(data.get("seen", {})))
