"""`fleet bench chaos`: faults at random moments of real fleet runs, and what they cost the job.

Each run is ``fleet up --speed 0 --until-done`` on one world and seed. Before it, a seeded RNG
(the seed and the run's number) draws K faults (:func:`schedule`), each at a random sim moment
between ``FIRST`` and ``LAST`` of the no-fault run's makespan, among ``KINDS``:

- ``kill-agent``: SIGKILL of an agent; once the coordinator has lost it, ``fleet respawn``;
- ``stop-agent``: SIGSTOP of an agent, SIGCONT ``STOP_S`` wall seconds later;
- ``kill-coordinator``: SIGKILL of the coordinator, ``fleet respawn`` ``COORD_DOWN_S`` later;
- ``rogue``: for ``ROGUE_S`` wall seconds, a client of the run's router (:class:`Rogue`)
  publishes fuzzed payloads on every key class and well-formed messages no receiver may
  believe (stamps far ahead of the sim clock, positions no robot can drive to, scans not from
  the robot's lidar, commands beyond the robot's speeds, senders not in the job).

A router restart is not among them: ``fleet up`` stops the whole fleet when its router dies.
Faults are made one after another (a fault due while another is made waits for it); those due
after the job ended are not made. With ``rogue_throughout`` a rogue also publishes from the
job's first auction to its end.

Per run (:func:`run_outcome`, from its report, events and output): finished or not, status,
coverage, makespan and its ratio to the no-fault run, the tasks lost (never done and not left
out as blocked or unreachable), per fault its detection (signal → the coordinator's ``lost``)
and reassignment (``lost`` → the last of its work ``reassigned``) times, or for the coordinator
the time to its ``resumed`` event; the processes that exited by themselves (any exit that is not
a SIGKILL the bench sent) and the logs that hold a traceback (a handler that failed and was
survived, or a crash). :func:`aggregate` sums the runs up.
"""

from __future__ import annotations

import json
import re
import signal
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import msgpack
import numpy as np

from fleet.bench.recovery import events_after, quantiles, to_reassign
from fleet.bus import Bus
from fleet.params import FleetConfig, load_fleet_config
from fleet.plausible import SimClock as BelievedClock
from fleet.plausible import clock_step_s
from fleet.protocol import (
    SCHEMA_VERSION,
    AwardAck,
    Bids,
    Clock,
    Heartbeat,
    Intent,
    Keys,
    LaserScan,
    Message,
    Odometry,
    PoseEstimate,
    RobotStatus,
    Twist,
)
from fleet.rundir import RunDirError
from fleet.supervisor.runner import RunningFleet

KINDS = ("kill-agent", "stop-agent", "kill-coordinator", "rogue")
# faults fall between these fractions of the no-fault run's makespan (sim time)
FIRST, LAST = 0.1, 0.8
STOP_S = 5.0
COORD_DOWN_S = 2.0
ROGUE_S = 10.0
# a rogue sends a burst of messages every this many wall seconds
ROGUE_PERIOD_S = 0.2
DETECT_TIMEOUT_S = 10.0
# a loss of the target noticed later than this (wall s) after its fault is not that fault's:
# the fault went unnoticed (a robot back before its silence was checked), the loss is another
NOTICED_WITHIN_S = 30.0
START_TIMEOUT_S = 120.0
# a stamp no sim clock reaches in a run
FAR_AHEAD_S = 1e9
# a robot no run has: ranked above every real one, so the others would give way to it
GHOST = "robot-00"
# every topic of a robot's keys, of the sim's and of the coordinator's
ROBOT_TOPICS = ("scan", "odom", "cmd_vel", "truth", "pose", "intent", "status", "map", "heartbeat")


@dataclass(frozen=True)
class Fault:
    """One fault: at sim second ``at_s``, of ``kind``, to process ``target``."""

    at_s: float
    kind: str
    target: str


def schedule(
    rng: np.random.Generator,
    faults: int,
    makespan_s: float,
    robots: int,
    kinds: Sequence[str] = KINDS,
) -> list[Fault]:
    """``faults`` faults in sim-time order, each at a uniform moment in [``FIRST``, ``LAST``] of
    ``makespan_s``, of a uniform kind; an agent's fault to a uniform one of ``robots``."""
    out = []
    for _ in range(faults):
        at = float(rng.uniform(FIRST, LAST) * makespan_s)
        kind = str(kinds[int(rng.integers(len(kinds)))])
        if kind in ("kill-agent", "stop-agent"):
            target = f"robot-{int(rng.integers(robots))}"
        elif kind == "kill-coordinator":
            target = "coordinator"
        else:
            target = "rogue"
        out.append(Fault(round(at, 2), kind, target))
    return sorted(out, key=lambda f: f.at_s)


# ---- the rogue ------------------------------------------------------------------------------


def fuzz_payloads(rng: np.random.Generator, kind: str) -> list[bytes]:
    """Payloads that must not decode as a ``kind`` message: random bytes, msgpack that is not a
    map, a map of another schema version, and this type with its fields of the wrong types."""
    junk = rng.integers(0, 256, int(rng.integers(1, 64)), dtype=np.uint8).tobytes()
    return [
        junk,
        msgpack.packb([1, 2, 3]),
        msgpack.packb({"_v": SCHEMA_VERSION + 7, "_t": kind}),
        msgpack.packb({"_v": SCHEMA_VERSION, "_t": kind, "stamp": "soon", "x": [None]}),
    ]


def implausible_messages(
    keys: Keys, robots: Sequence[str], now: float, cfg: FleetConfig, rng: np.random.Generator
) -> list[tuple[str, Message]]:
    """Well-formed messages that no receiver may believe at sim time ``now``: the keys and the
    messages. Positions are drawn anew every time, so no three agree on a jump."""
    far = FAR_AHEAD_S + float(rng.uniform(0, 1e6))
    x, y = (float(v) for v in rng.uniform(-50.0, 50.0, 2))
    lidar = cfg.lidar
    beams = lidar.beams
    good = np.full(beams, 1.0, dtype=np.float32)
    increment = lidar.fov / beams
    out: list[tuple[str, Message]] = [(keys.clock(), Clock(far, 1.0))]
    for rid in robots:
        points = np.array([[now, x, y], [now + 0.2, x + 30.0, y]])
        out += [
            (keys.robot(rid, "odom"), Odometry(far, 0.0, 0.0, 0.0, 0.0, 0.0)),
            (keys.robot(rid, "odom"), Odometry(now, x, y, 0.0, 0.0, 0.0)),
            (keys.robot(rid, "scan"), LaserScan(far, -lidar.fov / 2, increment, 0.1, 6.0, good)),
            (keys.robot(rid, "scan"), LaserScan(now, 0.0, 0.5, 0.0, 60.0, good[:90])),
            (keys.robot(rid, "cmd_vel"), Twist(far * 1e3, 0.2, 0.0)),
            (keys.robot(rid, "cmd_vel"), Twist(now, 40.0, 9.0)),
            (keys.robot(rid, "pose"), PoseEstimate(far, 0.0, 0.0, 0.0)),
            (keys.robot(rid, "pose"), PoseEstimate(now, x, y, 0.0)),
            (keys.robot(rid, "intent"), Intent(far, np.array([[far, x, y]]), 1, 1)),
            (keys.robot(rid, "intent"), Intent(now, points, 1, 1)),
            (keys.robot(rid, "status"), RobotStatus(far, "driving", "t00", 0.5, 1, 2, 0.0)),
            (keys.ack(rid), AwardAck(now, 10**6, GHOST)),
        ]
    ghost_points = np.array([[now, x, y], [now + 1.0, x, y]])
    zero, no = np.zeros(1), np.zeros(1, dtype=np.uint8)
    out += [
        (keys.robot(GHOST, "intent"), Intent(now, ghost_points, 1, 1)),
        (keys.robot(GHOST, "pose"), PoseEstimate(now, x, y, 0.0)),
        (keys.robot(GHOST, "status"), RobotStatus(now, "driving", "t00", 0.5, 1, 2, 0.0)),
        (keys.robot(GHOST, "heartbeat"), Heartbeat(now, 1, True)),
        (keys.bids(GHOST), Bids(now, 1, GHOST, ["t00"], zero, zero, no, no)),
    ]
    return out


def every_key(keys: Keys, robots: Iterable[str]) -> list[tuple[str, str]]:
    """(key, message type) of every key class a fleet uses, for the fuzzed payloads."""
    out = [
        (keys.clock(), "clock"),
        (keys.coverage(), "coverage"),
        (keys.collisions(), "collision"),
        (keys.coord_state(), "fleet_state"),
        (keys.events(), "event"),
        (keys.call(), "auction_call"),
    ]
    for rid in robots:
        out += [(keys.robot(rid, topic), topic) for topic in ROBOT_TOPICS]
        out += [
            (keys.plan(rid), "plan"),
            (keys.award(rid), "award"),
            (keys.ack(rid), "award_ack"),
            (keys.bids(rid), "bids"),
        ]
    return out


class Rogue:
    """A client of a run's router that publishes, every ``ROGUE_PERIOD_S`` while it runs, a
    fuzzed payload on every key class and every message of :func:`implausible_messages`."""

    def __init__(self, endpoint: str, fleet: str, robots: int, seed: int) -> None:
        self.cfg = load_fleet_config()
        self.robots = [f"robot-{i}" for i in range(robots)]
        self.rng = np.random.default_rng([seed, 29])
        self.bus = Bus("rogue", f"rogue-{seed}", [endpoint], fleet)
        self.clock = BelievedClock(clock_step_s(self.cfg.sim, self.cfg.agent), lambda *_: None)
        self.bus.subscribe(self.bus.keys.clock(), Clock, lambda _k, m: self.clock.hear(m.stamp))
        self.sent = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def burst(self) -> None:
        keys, now = self.bus.keys, self.clock.now
        for key, kind in every_key(keys, self.robots):
            payloads = fuzz_payloads(self.rng, kind)
            self.bus.session.put(key, payloads[int(self.rng.integers(len(payloads)))])
            self.sent += 1
        for key, msg in implausible_messages(keys, self.robots, now, self.cfg, self.rng):
            self.bus.session.put(key, msg.encode())
            self.sent += 1

    def _run(self, until: float) -> None:
        while not self._stop.is_set() and time.monotonic() < until:
            self.burst()
            self._stop.wait(ROGUE_PERIOD_S)

    def start(self, seconds: float = float("inf")) -> None:
        until = time.monotonic() + seconds
        self._thread = threading.Thread(target=self._run, args=(until,), daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
        self.bus.close()


# ---- one run ---------------------------------------------------------------------------------


def _last_seq(fleet: RunningFleet) -> int:
    return max((e["seq"] for e in fleet.events()), default=0)


def make_fault(fleet: RunningFleet, fault: Fault, rogue: Callable[[], Rogue]) -> dict[str, Any]:
    """Make ``fault`` now; what happened, for :func:`fault_outcome`. A target gone before the
    fault is made to its end (the fleet stopped under it: a process it cannot do without
    died) is noted as ``error``; the run's outcome says why it ended."""
    made: dict[str, Any] = {**asdict(fault), "seq": _last_seq(fleet), "sent": time.time()}
    try:
        _make(fleet, fault, rogue, made)
    except RunDirError as e:
        made["error"] = str(e)
    return made


def _make(
    fleet: RunningFleet, fault: Fault, rogue: Callable[[], Rogue], made: dict[str, Any]
) -> None:
    """Make ``fault``, noting in ``made`` what its respawn returned, or the rogue."""
    if fault.kind == "kill-agent":
        fleet.signal(fault.target, signal.SIGKILL)
        fleet.wait(lambda: events_after(fleet.events(), made["seq"], "lost", fault.target), 10.0)
        made["respawn"] = fleet.verb("respawn", fault.target).returncode
    elif fault.kind == "stop-agent":
        fleet.signal(fault.target, signal.SIGSTOP)
        time.sleep(STOP_S)
        fleet.signal(fault.target, signal.SIGCONT)
    elif fault.kind == "kill-coordinator":
        fleet.signal(fault.target, signal.SIGKILL)
        time.sleep(COORD_DOWN_S)
        made["respawn"] = fleet.verb("respawn", fault.target).returncode
    else:
        made["rogue"] = rogue()


def fault_outcome(events: list[dict[str, Any]], made: dict[str, Any]) -> dict[str, Any]:
    """Detection and reassignment of one fault made (:func:`make_fault`), from the run's
    events: ``lost`` of the target after it, the work it held ``reassigned``, and its
    ``rejoined``; for the coordinator, its ``resumed``."""
    out = {k: made[k] for k in ("at_s", "kind", "target")}
    out["fired"] = made.get("fired", True)
    if "error" in made:
        out["error"] = made["error"]
    seq, target = made.get("seq", 0), made["target"]
    if made["kind"] == "kill-coordinator":
        resumed = events_after(events, seq, "resumed")
        out["resumed_s"] = round(resumed[0]["wall"] - made["sent"], 3) if resumed else None
        return out
    if made["kind"] == "rogue" or not out["fired"]:
        return out
    lost = [
        e
        for e in events_after(events, seq, "lost", target)
        if e["wall"] - made["sent"] <= NOTICED_WITHIN_S
    ]
    out["detection_s"] = round(lost[0]["wall"] - made["sent"], 3) if lost else None
    out["reassignment_s"] = None
    out["rejoined"] = bool(events_after(events, seq, "rejoined", target))
    if lost:
        # the work it held when lost: reopened before it was lost again
        until = lost[1]["seq"] if len(lost) > 1 else float("inf")
        reopened = {
            e["task"]
            for e in events_after(events, lost[0]["seq"], "reopened", target)
            if e["seq"] < until
        }
        due = to_reassign(events_after(events, lost[0]["seq"], "rerouted"), reopened)
        done = [e for e in events_after(events, lost[0]["seq"], "reassigned") if e["task"] in due]
        if done:
            out["reassignment_s"] = round(max(e["wall"] for e in done) - lost[0]["wall"], 3)
        out["all_reassigned"] = {e["task"] for e in done} >= due
    return out


def tasks_lost(report: dict[str, Any]) -> list[str]:
    """The tasks of a finished job that were never done nor left out (blocked or unreachable)."""
    left_out = {t.get("id") for t in report.get("left_out") or []}
    return sorted(
        t["id"]
        for t in report.get("tasks") or []
        if t.get("state") not in ("done", "replaced") and t["id"] not in left_out
    )


EXIT = re.compile(r"(\S+) exited with code (-?\d+)")


def exits(output: str) -> list[tuple[str, int]]:
    """(process, exit code) of every process ``fleet up`` said exited during the run."""
    return [(n, int(c)) for n, c in EXIT.findall(re.sub(r"\s+", " ", output))]


def crashed(output: str, killed: Iterable[str]) -> list[str]:
    """The processes that exited by themselves: every exit but a SIGKILL of one the bench
    killed (each kill excuses one exit)."""
    excused = list(killed)
    out = []
    for name, code in exits(output):
        if code == -signal.SIGKILL and name in excused:
            excused.remove(name)
        else:
            out.append(f"{name} ({code})")
    return out


def tracebacks(run_dir: Path) -> dict[str, int]:
    """How many tracebacks each of the run dir's logs holds (those that hold any)."""
    out = {}
    for log in sorted(run_dir.glob("*.log")):
        n = log.read_text(errors="replace").count("Traceback (most recent call last)")
        if n:
            out[log.name] = n
    return out


def run_outcome(
    report: dict[str, Any] | None,
    made: list[dict[str, Any]],
    events: list[dict[str, Any]],
    output: str,
    base_makespan_s: float | None,
) -> dict[str, Any]:
    """One run's row (see the module docstring), without its run dir's tracebacks."""
    report = report or {}
    makespan = report.get("makespan_s")
    status = report.get("status")
    killed = [m["target"] for m in made if m["kind"] in ("kill-agent", "kill-coordinator")]
    return {
        "finished": status in ("done", "incomplete"),
        "status": status,
        "coverage": report.get("coverage"),
        "makespan_s": makespan,
        "makespan_ratio": (
            round(makespan / base_makespan_s, 3) if makespan and base_makespan_s else None
        ),
        "tasks_lost": tasks_lost(report) if report else None,
        "left_out": len(report.get("left_out") or []),
        "faults": [fault_outcome(events, m) for m in made],
        "crashed": crashed(output, killed),
        "dropped": report.get("dropped"),
    }


def one_run(
    run_dir: Path,
    world: str,
    robots: int,
    seed: int,
    faults: list[Fault],
    base_makespan_s: float | None,
    rogue_throughout: bool,
    progress: Callable[[str], None],
) -> dict[str, Any]:
    """One fleet run with ``faults`` made at their moments."""
    fleet = RunningFleet(run_dir, world, robots, seed)
    clock = fleet.clock()
    rogues: list[Rogue] = []
    made: list[dict[str, Any]] = []

    def rogue(seconds: float = ROGUE_S) -> Rogue:
        table = fleet.table()
        r = Rogue(table["endpoint"], table["fleet"], robots, seed + len(rogues))
        rogues.append(r)
        r.start(seconds)
        return r

    try:
        if rogue_throughout:
            fleet.wait(lambda: fleet.events("auction"), START_TIMEOUT_S)
            rogue(float("inf"))
        for f in faults:
            if not fleet.wait(lambda f=f: clock.t >= f.at_s, 900.0, poll=0.02):
                made.append({**asdict(f), "fired": False})
                continue
            progress(f"    {clock.t:6.1f} s sim: {f.kind} {f.target}")
            m = make_fault(fleet, f, rogue)
            made.append(m)
        report = fleet.finish()
    finally:
        for r in rogues:
            r.close()
        fleet.cleanup()
    for m in made:
        r = m.pop("rogue", None)
        if r is not None:
            m["rogue_sent"] = r.sent
    row = run_outcome(report, made, fleet.events(), fleet.output, base_makespan_s)
    row["rogue_sent"] = sum(r.sent for r in rogues)
    row["tracebacks"] = tracebacks(run_dir)
    row["run_dir"] = str(run_dir)
    return row


# ---- the bench ---------------------------------------------------------------------------------


def aggregate(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The runs summed up: how many finished, the fewest coverage, tasks lost, crashes, the
    faults made per kind with their detection and reassignment times, and the mean makespan
    ratio of the runs that met each kind."""
    faults = [f for r in rows for f in r["faults"] if f.get("fired", True)]
    per_kind: dict[str, Any] = {}
    for kind in KINDS:
        mine = [f for f in faults if f["kind"] == kind]
        ratios = [
            r["makespan_ratio"]
            for r in rows
            if r["makespan_ratio"] and any(f["kind"] == kind for f in r["faults"])
        ]
        per_kind[kind] = {
            "made": len(mine),
            "detection_s": quantiles([f["detection_s"] for f in mine if f.get("detection_s")]),
            "reassignment_s": quantiles(
                [f["reassignment_s"] for f in mine if f.get("reassignment_s") is not None]
            ),
            "resumed_s": quantiles([f["resumed_s"] for f in mine if f.get("resumed_s")]),
            "makespan_ratio_mean": round(float(np.mean(ratios)), 3) if ratios else None,
        }
    coverages = [r["coverage"] for r in rows if r["coverage"] is not None]
    return {
        "runs": len(rows),
        "finished": sum(r["finished"] for r in rows),
        "coverage_min": min(coverages) if coverages else None,
        "tasks_lost": sum(len(r["tasks_lost"] or []) for r in rows),
        "crashed": sum(len(r["crashed"]) for r in rows),
        "faults_made": len(faults),
        "per_kind": per_kind,
    }


def run_bench(
    root: Path,
    world: str,
    robots: int,
    seed: int,
    runs: int,
    faults: int,
    rogue_throughout: bool,
    progress: Callable[[str], None],
    base_makespan_s: float | None = None,
) -> dict[str, Any]:
    """A no-fault run (unless its makespan is given), then ``runs`` runs of ``faults`` faults
    each; written to bench.json."""
    root.mkdir(parents=True, exist_ok=True)
    base = None
    makespan = base_makespan_s
    if makespan is None:
        progress("no-fault run")
        base = one_run(root / "no-fault", world, robots, seed, [], None, False, progress)
        makespan = base["makespan_s"]
        progress(f"    {base['status']}: coverage {base['coverage']}, makespan {makespan} s")
    rows = []
    for k in range(runs):
        plan = schedule(np.random.default_rng([seed, k]), faults, makespan or 100.0, robots)
        progress(f"run {k + 1}/{runs}: " + ", ".join(f"{f.kind}@{f.at_s:.0f}s" for f in plan))
        row = one_run(
            root / f"run-{k:02d}", world, robots, seed, plan, makespan, rogue_throughout, progress
        )
        row["run"] = k
        progress(
            f"    {row['status']}: coverage {row['coverage']}, makespan ×{row['makespan_ratio']}, "
            f"tasks lost {len(row['tasks_lost'] or [])}, crashed {row['crashed'] or 'none'}"
        )
        rows.append(row)
    result = {
        "world": world,
        "robots": robots,
        "seed": seed,
        "faults_per_run": faults,
        "rogue_throughout": rogue_throughout,
        "root": str(root),
        "no_fault": base,
        "base_makespan_s": makespan,
        "runs": rows,
        "summary": aggregate(rows),
    }
    (root / "bench.json").write_text(json.dumps(result, indent=2) + "\n")
    return result


def table_lines(result: dict[str, Any]) -> list[str]:
    """The per-run table and the summary."""
    base = result["no_fault"]
    lines = [
        f"no-fault run: {base['status']}, coverage {base['coverage']}, makespan "
        f"{base['makespan_s']} s"
        if base
        else f"no-fault makespan given: {result['base_makespan_s']} s",
        "run  status      coverage  makespan ×  lost  crashed  faults (kind@sim s: detection / "
        "reassignment s)",
    ]
    for r in result["runs"]:
        faults = "; ".join(_fault_text(f) for f in r["faults"]) or "-"
        lines.append(
            f"{r['run']:>3}  {r['status']!s:<10}  {r['coverage']!s:>8}  "
            f"{r['makespan_ratio']!s:>10}  {len(r['tasks_lost'] or []):>4}  "
            f"{len(r['crashed']):>7}  {faults}"
        )
    s = result["summary"]
    lines.append(
        f"finished {s['finished']}/{s['runs']}, coverage min {s['coverage_min']}, tasks lost "
        f"{s['tasks_lost']}, crashed {s['crashed']}, faults made {s['faults_made']}"
    )
    for kind, k in s["per_kind"].items():
        d, a, r = k["detection_s"], k["reassignment_s"], k["resumed_s"]
        times = (
            f"resumed median {r['median']} s (max {r['max']})"
            if kind == "kill-coordinator"
            else f"detection median {d['median']} s (max {d['max']}), reassignment median "
            f"{a['median']} s (max {a['max']})"
        )
        lines.append(
            f"  {kind:<16} made {k['made']:>2}  {times}  makespan × (mean of the runs with "
            f"one) {k['makespan_ratio_mean']}"
        )
    return lines


def _fault_text(f: dict[str, Any]) -> str:
    head = f"{f['kind']} {f['target']}@{f['at_s']:.0f}"
    if not f.get("fired", True):
        return head + " (not made: the job had ended)"
    if f["kind"] == "kill-coordinator":
        return f"{head}: resumed {f.get('resumed_s')}"
    if f["kind"] == "rogue":
        return head
    return f"{head}: {f.get('detection_s')} / {f.get('reassignment_s')}"
