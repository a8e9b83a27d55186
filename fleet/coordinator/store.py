"""The coordinator's job state on disk (SQLite), written as it changes, read back on restart.

Tables: ``meta`` (phase, counters), ``tasks`` (path, cells, state, owner, queue position,
direction, swept pieces), ``robots`` (liveness, last report, heartbeat, restarts, award
sequence numbers), ``plans`` (the plan each robot drives, so a restarted coordinator serves the
same plan id and the robot keeps driving), ``events`` and ``bids`` (the auction log). WAL
journal, so ``fleet status`` reads while the coordinator writes. The file names the version
of its layout (``meta.store_version``) and the job's fleet, world and robot count
(``meta.fleet``, ``world``, ``expected_robots``). A coordinator started on an existing file
resumes it only if it is whole and its own: a file that is empty, not SQLite, cut short
(smaller than its header says), damaged (``PRAGMA quick_check``), of another layout or of
another fleet, world or robot count is refused with :class:`StoreError`, naming the file and
why; it is never resumed as if it were this job's, nor replaced by a fresh start.
"""

from __future__ import annotations

import json
import sqlite3
import time
from pathlib import Path

import numpy as np

from fleet.coordinator.job import Job, RobotRecord, TaskRecord
from fleet.protocol import Plan
from planners.auction import Task

STORE_VERSION = 5
SQLITE_MAGIC = b"SQLite format 3\x00"
SQLITE_HEADER_BYTES = 100
SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT);
CREATE TABLE IF NOT EXISTS tasks (
    id TEXT PRIMARY KEY, parent TEXT, area_m2 REAL, time_s REAL, path BLOB, cells TEXT,
    state TEXT, owner TEXT, position INTEGER, reverse INTEGER, swept BLOB,
    created_wall REAL, done_wall REAL, tried TEXT, blocked_by TEXT, kind TEXT);
CREATE TABLE IF NOT EXISTS robots (
    id TEXT PRIMARY KEY, liveness TEXT, state TEXT, task TEXT, progress REAL,
    heartbeat_wall REAL, restarts INTEGER, award_seq INTEGER, acked_seq INTEGER, x REAL, y REAL);
CREATE TABLE IF NOT EXISTS plans (
    robot TEXT PRIMARY KEY, plan_id INTEGER, task TEXT, waypoints BLOB, sweep_from INTEGER,
    stamp REAL, chain TEXT, chain_starts BLOB, kind TEXT);
CREATE TABLE IF NOT EXISTS events (
    seq INTEGER PRIMARY KEY AUTOINCREMENT, wall REAL, sim REAL, kind TEXT, robot TEXT,
    task TEXT, detail TEXT);
CREATE TABLE IF NOT EXISTS bids (
    round INTEGER, task TEXT, robot TEXT, marginal_s REAL, total_s REAL, reverse INTEGER,
    won INTEGER, wall REAL);
"""


class StoreError(ValueError):
    """A state file that cannot be resumed; the message names the file and why."""


FRESH = "remove it (or keep it aside) to start the job afresh"


def _check_whole(path: Path) -> None:
    """Refuse a file that is not a whole SQLite database: empty, something else, or shorter
    than its header says (checked where the header's size is valid and no write-ahead log holds
    pages beyond the file)."""
    size = path.stat().st_size
    if size == 0:
        raise StoreError(f"{path}: empty (0 bytes), not a job state file; {FRESH}")
    with path.open("rb") as f:
        head = f.read(SQLITE_HEADER_BYTES)
    if not head.startswith(SQLITE_MAGIC):
        raise StoreError(f"{path}: not an SQLite database (it begins {head[:16]!r}); {FRESH}")
    if len(head) < SQLITE_HEADER_BYTES:
        raise StoreError(f"{path}: cut short: {size} bytes, less than an SQLite header; {FRESH}")
    page_size = int.from_bytes(head[16:18], "big")
    page_size = 65536 if page_size == 1 else page_size
    pages = int.from_bytes(head[28:32], "big")
    size_valid = head[24:28] == head[92:96]
    wal = path.with_name(path.name + "-wal")
    if size_valid and not wal.exists() and size < pages * page_size:
        raise StoreError(
            f"{path}: cut short: {size} bytes of the {pages * page_size} its header names; {FRESH}"
        )


def _identity(values: dict[str, object]) -> str:
    parts = []
    if "fleet" in values:
        parts.append(f"fleet {values['fleet']!r}")
    if "world" in values:
        parts.append(f"world {values['world']!r}")
    if "expected_robots" in values:
        parts.append(f"{values['expected_robots']} robots")
    return ", ".join(parts)


class JobStore:
    """One SQLite file; every ``save_*`` commits, so a SIGKILL loses at most the change in
    flight."""

    def __init__(
        self,
        path: Path,
        *,
        fleet: str | None = None,
        world: str | None = None,
        robots: int | None = None,
    ) -> None:
        """Open (or start) the job state in ``path``. ``fleet``, ``world`` and ``robots``, when
        given, are the job's: a new file records them, an existing one must hold the same."""
        self.path = path
        path.parent.mkdir(parents=True, exist_ok=True)
        existing = path.exists()
        if existing:
            _check_whole(path)
        self.db = sqlite3.connect(str(path), check_same_thread=False, isolation_level=None)
        ours = {"fleet": fleet, "world": world, "expected_robots": robots}
        ours = {k: v for k, v in ours.items() if v is not None}
        try:
            self._open(existing, ours)
        except StoreError:
            self.db.close()
            raise
        except (sqlite3.DatabaseError, json.JSONDecodeError) as e:
            self.db.close()
            raise StoreError(f"{path}: damaged ({e}); {FRESH}") from None

    def _open(self, existing: bool, ours: dict[str, object]) -> None:
        path = self.path
        if existing:
            problems = [row[0] for row in self.db.execute("PRAGMA quick_check").fetchall()]
            if problems != ["ok"]:
                raise StoreError(f"{path}: damaged ({problems[0]}); {FRESH}")
            tables = {r[0] for r in self.db.execute("SELECT name FROM sqlite_master")}
            if "meta" not in tables:
                names = ", ".join(sorted(tables)) or "none"
                raise StoreError(
                    f"{path}: not a job state file of the coordinator (its tables: {names}); "
                    f"{FRESH}"
                )
        self.db.execute("PRAGMA journal_mode=WAL")
        self.db.execute("PRAGMA synchronous=NORMAL")
        self.db.executescript(SCHEMA)
        meta = self.meta()
        if not existing:
            self.set_meta(store_version=STORE_VERSION, **ours)
            return
        found = meta.get("store_version", "none")
        if found != STORE_VERSION:
            raise StoreError(
                f"{path}: a job state file of layout version {found}, not {STORE_VERSION}: "
                "it was written by another version of fleet; start the job with a new state file"
            )
        theirs = {k: meta.get(k) for k in ours}
        if theirs != ours:
            raise StoreError(
                f"{path}: the job of {_identity(theirs)}, not of {_identity(ours)}: a coordinator "
                "resumes only its own fleet's job; give it the same --fleet, --world and --robots, "
                "or another state file"
            )

    def close(self) -> None:
        self.db.close()

    # ---- writing ------------------------------------------------------------------------

    def set_meta(self, **values: object) -> None:
        with self.db:
            self.db.executemany(
                "INSERT OR REPLACE INTO meta VALUES (?, ?)",
                [(k, json.dumps(v)) for k, v in values.items()],
            )

    def clear_job(self) -> None:
        """Forget the tasks and plans of a finished job (its events and bids stay)."""
        with self.db:
            self.db.execute("DELETE FROM tasks")
            self.db.execute("DELETE FROM plans")

    def save_tasks(self, records: list[TaskRecord]) -> None:
        now = time.time()
        rows = [
            (
                r.task.id,
                r.parent,
                r.task.area_m2,
                r.task.time_s,
                np.ascontiguousarray(r.task.path, dtype="<f8").tobytes(),
                json.dumps(list(r.task.cells)),
                r.state,
                r.owner,
                r.position,
                int(r.reverse),
                np.asarray(r.swept, dtype=np.uint8).tobytes(),
                now,
                now if r.state == "done" else None,
                json.dumps(sorted(r.tried)),
                r.blocked_by,
                r.task.kind,
            )
            for r in records
        ]
        with self.db:
            self.db.executemany(
                "INSERT INTO tasks VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?) ON CONFLICT(id) DO "
                "UPDATE SET state=excluded.state, owner=excluded.owner, "
                "position=excluded.position, reverse=excluded.reverse, swept=excluded.swept, "
                "tried=excluded.tried, blocked_by=excluded.blocked_by, "
                "done_wall=COALESCE(tasks.done_wall, excluded.done_wall)",
                rows,
            )

    def save_robots(self, records: list[RobotRecord]) -> None:
        rows = [
            (
                r.id,
                r.liveness,
                r.state,
                r.task,
                r.progress,
                r.heartbeat_wall,
                r.restarts,
                r.award_seq,
                r.acked_seq,
                r.xy[0] if r.xy else None,
                r.xy[1] if r.xy else None,
            )
            for r in records
        ]
        with self.db:
            self.db.executemany(
                "INSERT OR REPLACE INTO robots VALUES (?,?,?,?,?,?,?,?,?,?,?)", rows
            )

    def save_plan(self, robot: str, plan: Plan) -> None:
        with self.db:
            self.db.execute(
                "INSERT OR REPLACE INTO plans VALUES (?,?,?,?,?,?,?,?,?)",
                (
                    robot,
                    plan.plan_id,
                    plan.task,
                    np.ascontiguousarray(plan.waypoints, dtype="<f8").tobytes(),
                    plan.sweep_from,
                    plan.stamp,
                    json.dumps(list(plan.chain)),
                    np.ascontiguousarray(plan.chain_starts, dtype="<i4").tobytes(),
                    plan.kind,
                ),
            )

    def add_event(self, wall: float, sim: float, kind: str, robot: str, task: str, detail: str):
        with self.db:
            self.db.execute(
                "INSERT INTO events (wall, sim, kind, robot, task, detail) VALUES (?,?,?,?,?,?)",
                (wall, sim, kind, robot, task, detail),
            )

    def add_bids(self, rows: list[tuple]) -> None:
        """(round, task, robot, marginal_s, total_s, reverse, won) rows of one auction round."""
        now = time.time()
        with self.db:
            self.db.executemany(
                "INSERT INTO bids VALUES (?,?,?,?,?,?,?,?)", [(*r, now) for r in rows]
            )

    # ---- reading ------------------------------------------------------------------------

    def meta(self) -> dict[str, object]:
        return {k: json.loads(v) for k, v in self.db.execute("SELECT key, value FROM meta")}

    def load_job(self, job: Job) -> None:
        """Fill ``job`` with the stored tasks and robots (robots come back ``lost`` until they
        are heard from again)."""
        for row in self.db.execute(
            "SELECT id, parent, area_m2, time_s, path, cells, state, owner, position, reverse, "
            "swept, tried, blocked_by, kind FROM tasks ORDER BY rowid"
        ):
            (
                tid,
                parent,
                area,
                t_s,
                path,
                cells,
                state,
                owner,
                pos,
                rev,
                swept,
                tried,
                by,
                kind,
            ) = row
            try:
                task = Task(
                    tid,
                    np.frombuffer(path, dtype="<f8").reshape(-1, 2).copy(),
                    float(area),
                    float(t_s),
                    tuple(json.loads(cells)),
                    kind,
                )
            except ValueError as e:  # e.g. a kind this version no longer has
                raise StoreError(f"{self.path}: cannot resume its job: {e}") from e
            job.tasks[tid] = TaskRecord(
                task,
                state,
                owner,
                int(pos),
                bool(rev),
                parent,
                np.frombuffer(swept, dtype=np.uint8).astype(bool),
                frozenset(json.loads(tried or "[]")),
                by,
            )
        for row in self.db.execute(
            "SELECT id, liveness, state, task, progress, heartbeat_wall, restarts, award_seq, "
            "acked_seq, x, y FROM robots"
        ):
            rid, live, state, task, prog, hb, restarts, aseq, ack, x, y = row
            job.robots[rid] = RobotRecord(
                rid,
                live,
                False,
                state or "",
                task or "",
                float(prog or 0.0),
                float(hb or 0.0),
                int(restarts or 0),
                int(aseq or 0),
                int(ack or 0),
                (float(x), float(y)) if x is not None else None,
            )

    def plans(self) -> dict[str, Plan]:
        out = {}
        for robot, pid, task, wps, sweep_from, stamp, chain, starts, kind in self.db.execute(
            "SELECT robot, plan_id, task, waypoints, sweep_from, stamp, chain, chain_starts, kind "
            "FROM plans"
        ):
            wp = np.frombuffer(wps, dtype="<f8").reshape(-1, 2).copy()
            out[robot] = Plan(
                float(stamp),
                int(pid),
                task,
                wp,
                int(sweep_from),
                json.loads(chain),
                np.frombuffer(starts, dtype="<i4").astype(np.int32),
                kind=kind,
            )
        return out
