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
  two queues. So does a robot that is alive but stuck (``release``).
- Work no robot can do is never counted done. A task that ends with pieces unswept goes back to
  the market as its remainder, remembering who tried it (``tried``); once every robot in the
  market has tried a task, it is ``unreachable``. A task or stretch of one that lies under or
  behind a lost robot's body is ``blocked`` by that body (``replace``). Work left open because
  no robot can work any more (each lost or out of charge) is ``stranded`` (``strand``). All
  three open again when the world changes: a body goes, or a robot joins (``reopen``). The job
  is finished when no task is open or assigned, and ``incomplete`` when it finished with work
  left out.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from planners.auction import Task, ahead_of, remainder
from planners.auction.detour import part_of
from planners.coverage.params import CoverageParams
from planners.robot import RobotSpec

OPEN, ASSIGNED, DONE, REPLACED = "open", "assigned", "done", "replaced"
BLOCKED, UNREACHABLE, STRANDED = "blocked", "unreachable", "stranded"
GONE = "gone"
# states of work that is over: done, gone, or left out for good unless the world changes
SETTLED = (DONE, REPLACED, BLOCKED, UNREACHABLE, STRANDED, GONE)
LEFT_OUT = (BLOCKED, UNREACHABLE, STRANDED)
ALIVE, LOST, REJOINED = "alive", "lost", "rejoined"
# a robot whose battery ran out away from a dock: it stands for good (RobotRecord.docking)
EMPTY = "empty"
# an exploring job's frontier tasks (fleet.coordinator.exploring): "f001", "f002", ...
FRONTIER_PREFIX = "f"


@dataclass
class TaskRecord:
    task: Task
    state: str = OPEN
    owner: str | None = None
    position: int = 0
    reverse: bool = False
    parent: str | None = None
    swept: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    # robots that drove it and left pieces unswept, or could not get to it
    tried: frozenset[str] = frozenset()
    # the lost robot whose body lies in its way (state blocked)
    blocked_by: str | None = None

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
    # its battery as its status reports it: charge (fraction; -1 without a battery heard) and
    # whether a dock charges it; ``docking`` names the dock trip that keeps it out of the
    # market ("" while it works)
    charge: float = -1.0
    charging: bool = False
    docking: str = ""

    @property
    def in_market(self) -> bool:
        return self.liveness != LOST and self.ready and self.xy is not None and not self.docking


class Job:
    """Tasks and robots; every method returns what changed so the shell can persist and tell."""

    def __init__(self, params: CoverageParams, spec: RobotSpec, wall_clearance: float) -> None:
        """``params`` and the robot's ``spec`` time the tasks cut from others; robot centres
        keep ``spec.radius + wall_clearance`` from obstacles, a lost robot's body included."""
        self.params = params
        self.spec = spec
        self.wall_clearance = wall_clearance
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
        out = {OPEN: 0, ASSIGNED: 0, DONE: 0, BLOCKED: 0, UNREACHABLE: 0, STRANDED: 0}
        for r in self.tasks.values():
            if r.state in out:
                out[r.state] += 1
        return out

    @property
    def finished(self) -> bool:
        """No task is open or assigned: every one is done, or left out."""
        return bool(self.tasks) and all(r.state in SETTLED for r in self.tasks.values())

    def left_out(self) -> list[TaskRecord]:
        """The tasks no robot could do: blocked by a body, unreachable, or stranded."""
        return [r for r in self.tasks.values() if r.state in LEFT_OUT]

    @property
    def incomplete(self) -> bool:
        return self.finished and bool(self.left_out())

    def market(self) -> list[str]:
        """Robots that may bid: not lost, localized, with a known pose."""
        return sorted(rid for rid, r in self.robots.items() if r.in_market)

    def bidders(self) -> list[str]:
        """Robots that may bid now or once back from charging: whether every one has tried a
        task (none out charging is left out of that)."""
        return sorted(
            rid
            for rid, r in self.robots.items()
            if r.liveness != LOST and r.ready and r.xy is not None and r.docking != EMPTY
        )

    # ---- transitions --------------------------------------------------------------------

    def add_tasks(self, tasks: tuple[Task, ...]) -> None:
        for t in tasks:
            self.tasks[t.id] = TaskRecord(t)

    def start_over(self, tasks: tuple[Task, ...]) -> None:
        """A new job on the same floor: ``tasks`` replace every task of the one before, all
        open; the robots, their liveness and their award numbers stay."""
        self.tasks = {}
        self.add_tasks(tasks)

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
                    clearance = 2 * (self.spec.radius + self.wall_clearance)
                    rest = ahead_of(
                        rec.task,
                        np.array(robot.xy),
                        rec.reverse,
                        clearance,
                        new_id,
                        self.params,
                        self.spec,
                    )
                else:
                    rest = remainder(rec.task, rec.swept, new_id, self.params, self.spec)
                rec.state, rec.owner = REPLACED, None
                if rest is not None:
                    self.tasks[rest.id] = TaskRecord(rest, parent=rec.task.id)
                    made.append(rest.id)
                    reopened.append(rest.id)
            else:
                rec.state, rec.owner, rec.reverse = OPEN, None, False
                reopened.append(rec.task.id)
        return reopened, made

    def give_back(self, rid: str, task_id: str, tried: bool = True) -> str | None:
        """``rid``'s plan ended with pieces of ``task_id`` unswept (waypoints it gave up, often
        because a peer stood in the way for a while, or because no robot of its size gets
        there): the remainder of its unswept pieces goes back to the market, remembering that
        ``rid`` tried it unless ``tried`` is false (a peer held it up), and its id is returned;
        None when nothing is left unswept."""
        rec = self.tasks.get(task_id)
        if rec is None or rec.state != ASSIGNED or rec.owner != rid:
            return None
        rest = remainder(rec.task, rec.swept, self._next_id(task_id), self.params, self.spec)
        if rest is None:
            return None
        rec.state, rec.owner = REPLACED, None
        by = {rid} if tried else set()
        self.tasks[rest.id] = TaskRecord(rest, parent=task_id, tried=rec.tried | by)
        return rest.id

    def release(self, rid: str, tried: bool = True) -> list[str]:
        """``rid`` is alive but makes no progress: the unswept remainder of the task it drives
        goes back to the market as a new task that it has tried (unless ``tried`` is false: a
        peer held it up), its unstarted tasks open again; the tasks opened are returned."""
        reopened = []
        for i, rec in enumerate(self.queue(rid)):
            if i == 0 and rec.started:
                rest = self.give_back(rid, rec.task.id, tried)
                if rest is None:
                    self.finish(rid, rec.task.id)
                else:
                    reopened.append(rest)
            else:
                rec.state, rec.owner, rec.reverse = OPEN, None, False
                if i == 0 and tried:
                    rec.tried = rec.tried | {rid}
                reopened.append(rec.task.id)
        return reopened

    def take_back(self, task_id: str) -> list[str]:
        """Take ``task_id`` and the tasks queued after it back from its owner: each opens
        again, or, if its owner has swept part of it, its remainder does (a new task; the
        owner has not tried it and failed, it was taken from it); the ids opened, none when
        ``task_id`` is not assigned."""
        rec = self.tasks.get(task_id)
        if rec is None or rec.state != ASSIGNED or rec.owner is None:
            return []
        out = []
        for later in self.queue(rec.owner):
            if later.position < rec.position:
                continue
            if later.started:
                rest = remainder(
                    later.task, later.swept, self._next_id(later.task.id), self.params, self.spec
                )
                if rest is None:
                    later.state = DONE
                    continue
                later.state, later.owner = REPLACED, None
                self.tasks[rest.id] = TaskRecord(rest, parent=later.task.id, tried=later.tried)
                out.append(rest.id)
            else:
                later.state, later.owner, later.reverse = OPEN, None, False
                out.append(later.task.id)
        return out

    def replace(
        self,
        task_id: str,
        parts: tuple[np.ndarray, ...],
        blocked: Sequence[tuple[np.ndarray, float]],
        body: str,
    ) -> tuple[list[str], list[str]]:
        """``task_id`` (open) cannot be driven as planned since ``body`` lies in its way: it
        is replaced by tasks driving ``parts`` (open: the drivable runs of its path, joined
        round the body where they can be) and by ``blocked`` (the stretches under or behind the
        body, blocked by it, each with the area of floor it puts out of reach), paths (N, 2);
        (the open ids, the blocked ids)."""
        rec = self.tasks[task_id]
        if rec.state != OPEN:
            raise ValueError(f"task {task_id} is {rec.state}, not open")
        rec.state = REPLACED
        made: tuple[list[str], list[str]] = ([], [])
        pieces = [(p, None) for p in parts] + list(blocked)
        for path, area in pieces:
            if len(path) < 2:
                continue
            state, ids = (OPEN, made[0]) if area is None else (BLOCKED, made[1])
            task = part_of(rec.task, path, self._next_id(task_id), self.params, self.spec)
            if area is not None:
                task = dataclasses.replace(task, area_m2=area)
            self.tasks[task.id] = TaskRecord(
                task,
                state,
                parent=task_id,
                tried=rec.tried if state == OPEN else frozenset(),
                blocked_by=body if state == BLOCKED else None,
            )
            ids.append(task.id)
        return made

    def settle_unreachable(self) -> list[str]:
        """Open tasks every robot that may bid (:meth:`bidders`) has tried become unreachable;
        their ids."""
        market = set(self.bidders())
        out = []
        for rec in self.open_tasks():
            if market and market <= rec.tried:
                rec.state = UNREACHABLE
                out.append(rec.task.id)
        return out

    def strand(self) -> list[str]:
        """No robot can work any more (each is lost or out of charge): every open task is
        ``stranded`` (not ``unreachable``: no robot with charge left tried it); their ids."""
        out = []
        for rec in self.open_tasks():
            rec.state = STRANDED
            out.append(rec.task.id)
        return out

    def reopen(self, body: str | None = None) -> list[str]:
        """The world changed: the tasks ``body`` blocked (with ``body`` given), and the
        unreachable tasks some robot in the market has not tried, and the stranded ones once a
        robot may bid again, open again; their ids."""
        market = set(self.bidders())
        out = []
        for rec in self.tasks.values():
            freed = rec.state == BLOCKED and body is not None and rec.blocked_by == body
            retry = rec.state == UNREACHABLE and not market <= rec.tried
            retry = retry or (rec.state == STRANDED and bool(market))
            if freed or retry:
                rec.state, rec.blocked_by = OPEN, None
                out.append(rec.task.id)
        return out

    def drop(self, task_id: str) -> str | None:
        """``task_id``, open, assigned or unreachable, is no longer wanted (its frontier
        vanished: the robots mapped it another way): it is ``gone``; the robot that held it, if
        any (its queue closes up behind it)."""
        rec = self.tasks.get(task_id)
        if rec is None or rec.state not in (OPEN, ASSIGNED, UNREACHABLE):
            return None
        owner = rec.owner if rec.state == ASSIGNED else None
        rec.state, rec.owner = GONE, None
        return owner

    def next_id(self, task_id: str) -> str:
        """A fresh id for a task made from ``task_id``: "t07" → "t07.1", "t07.1" → "t07.2"."""
        return self._next_id(task_id)

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
