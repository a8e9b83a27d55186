"""`fleet bench auction`: what one auction lot costs with many robots and many tasks, over a real
Zenoh router, against the same auctions run in one process.

The floor's coverage tour (the coordinator's, from the dock) is cut into about ``tasks`` tasks;
``robots`` bidder processes stand at seeded free spots of the floor, each with its own Zenoh
session to a router of its own process, pricing calls as an agent does
(:class:`agents.bidding.Bidder` answering with :meth:`agents.market.MarketClient.bids`: travel
on the floor plan, its won queue from its awards) and acknowledging each award. The bench's own
process is the coordinator's side: the real :class:`fleet.coordinator.auctioneer.Auctioneer`
sells every task, one lot a round (what the market does after the first allocation, when it
sells withdrawn or lost work task by task), sends the winner its queue and waits for its
acknowledgement before the next round, as the market does.

A lot's figure is its wall time from the call to the winner's acknowledgement, split into the
bids (call to the last answer) and the rest (award, queue, acknowledgement); the coordinator's
CPU per lot (the bench process: the auctioneer and its Zenoh session); each robot's CPU per
answer. The baseline is :func:`planners.auction.allocate` on the same tasks, poses and travel
in one process (no bus): its wall time per lot, and its makespan against the live auction's.
"""

from __future__ import annotations

import multiprocessing as mp
import statistics
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fleet.params import FleetConfig, load_fleet_config
from planners import auction
from planners.auction import split_tour
from planners.auction.allocation import Allocation
from planners.grid import GridMap
from planners.polyline import densify

# how long robots and the router have to start (s)
START_TIMEOUT_S = 120.0
# the longest a round may wait for its answers, and a winner for its acknowledgement (s)
ROUND_TIMEOUT_S = 10.0
# the tour is cut at points this far apart at most, so that it can be cut into many tasks (m)
CUT_STEP_M = 0.25


@dataclass(frozen=True)
class Floor:
    """What every process of the bench needs: the floor plan, the tasks and where robots stand."""

    grid: GridMap
    tasks: tuple[auction.Task, ...]
    poses: tuple[tuple[float, float, float], ...]
    speed: float
    radius: float


def make_floor(world: str, robots: int, tasks: int, seed: int, cfg: FleetConfig) -> Floor:
    """The coordinator's tour of ``world`` cut into at least ``tasks`` tasks where it has the
    points for them (cut at points at most ``CUT_STEP_M`` apart), and ``robots`` distinct
    seeded free spots a robot centre reaches."""
    from fleet.config import resolve_world
    from fleet.coordinator.planning import TaskPlanner
    from fleet.world import load_world

    planner = TaskPlanner(load_world(resolve_world(world), cfg.robot.radius), cfg)
    robot = planner.robot
    plan = planner.spec.plan(planner.grid, [planner.dock], robot)
    path = densify(plan.paths[0], CUT_STEP_M)
    target_s = plan.metrics.makespan_s / tasks
    cut: tuple[auction.Task, ...] = ()
    # the cut prefers the transits near each target, so it gives fewer tasks than asked for:
    # shorter targets until it gives enough (or the points run out)
    for _ in range(8):
        cut = split_tour(path, plan.cell_labels, planner.grid, target_s, planner.params, robot)
        if len(cut) >= tasks:
            break
        target_s *= min(len(cut) / tasks, 0.98)
    spots = np.argwhere(planner.reachable)
    if len(spots) < robots:
        raise ValueError(f"{world}: {len(spots)} free spots for {robots} robots")
    rng = np.random.default_rng(seed)
    picked = spots[rng.choice(len(spots), robots, replace=False)]
    xy = planner.grid.cell_to_world(picked)
    poses = tuple((float(x), float(y), 0.0) for x, y in xy)
    return Floor(planner.grid, cut, poses, cfg.agent.transit_speed, cfg.robot.radius)


def robot_name(i: int) -> str:
    return f"robot-{i}"


def _router_main(endpoint: str, ready: Any, stop: Any) -> None:
    from fleet.bus import open_router

    session = open_router([endpoint])
    ready.set()
    stop.wait()
    session.close()


def _bidder_main(endpoint: str, i: int, floor: Floor, ready: Any, stop: Any, out: Any) -> None:
    """One robot's market, as an agent has it: prices every call, takes every award."""
    from agents.bidding import Bidder
    from agents.market import MarketClient
    from fleet.bus import Bus
    from fleet.protocol import AuctionCall, Award, AwardAck, Bids

    rid = robot_name(i)
    market = MarketClient(rid, floor.speed, floor.radius, 0.65, 0.2)
    market.use_floor(floor.grid)
    lock = threading.Lock()
    pose = floor.poses[i]
    done = threading.Event()
    with Bus("robot", rid, [endpoint]) as bus:

        def answer(call: AuctionCall) -> Bids:
            with lock:
                return market.bids(call, market.commitment(pose, None, [], 0.0))

        def on_award(_key: str, msg: Award) -> None:
            with lock:
                market.on_award(msg)
                seq = market.seq
            bus.publish(bus.keys.ack(rid), AwardAck(0.0, seq, rid), True)

        bidder = Bidder(bus, rid, answer, done)
        bus.subscribe(bus.keys.call(), AuctionCall, bidder.on_call)
        bus.subscribe(bus.keys.award(rid), Award, on_award)
        thread = threading.Thread(target=bidder.loop, daemon=True)
        thread.start()
        cpu = time.process_time()
        ready.set()
        stop.wait()
        done.set()
        thread.join(5.0)
        out.put((rid, bidder.answered, time.process_time() - cpu))


class _Acks:
    """The robots' award acknowledgements, as the coordinator's receiver keeps them."""

    def __init__(self) -> None:
        self.seq: dict[str, int] = {}
        self.cond = threading.Condition()

    def on_ack(self, _key: str, msg: Any) -> None:
        with self.cond:
            self.seq[msg.robot] = max(self.seq.get(msg.robot, 0), msg.seq)
            self.cond.notify_all()

    def wait(self, robot: str, seq: int, timeout: float) -> bool:
        with self.cond:
            return self.cond.wait_for(lambda: self.seq.get(robot, 0) >= seq, timeout)


def _sell_all(bus: Any, floor: Floor, robots: list[str], progress: Any) -> dict[str, Any]:
    """Every task sold one lot a round by the real auctioneer; per-lot figures."""
    from fleet.coordinator.auctioneer import Auctioneer
    from fleet.params import CoordinatorParams
    from fleet.protocol import Award, AwardAck, Bids

    sales: list[Any] = []
    params = CoordinatorParams(bid_timeout_s=ROUND_TIMEOUT_S)
    auctioneer = Auctioneer(bus.keys, bus.publish, params, sales.append)
    acks = _Acks()
    bus.subscribe(bus.keys.all_bids(), Bids, auctioneer.on_bid)
    bus.subscribe(bus.keys.ack("*"), AwardAck, acks.on_ack)
    open_ = {t.id: t for t in floor.tasks}
    queues: dict[str, list[tuple[str, np.ndarray, np.ndarray, float]]] = {r: [] for r in robots}
    allocation: dict[str, list[tuple[str, bool]]] = {r: [] for r in robots}
    lot_s, bids_s, cpu_s, answers, unanswered = [], [], [], [], 0
    market = set(robots)
    while open_:
        t0, c0 = time.perf_counter(), time.process_time()
        lots = {tid: auction.task_lot(t) for tid, t in open_.items()}
        rnd = auctioneer.call(0.0, lots, frozenset(robots))
        t1 = time.perf_counter()
        sale = auctioneer.award(rnd, market)
        if sale is None:
            break
        best, task = sale.best, open_.pop(sale.best.task)
        first, last = (task.exit, task.entry) if best.reverse else (task.entry, task.exit)
        queue = queues[best.robot]
        queue.append((task.id, first, last, task.time_s))
        allocation[best.robot].append((task.id, best.reverse))
        award = Award(
            0.0,
            len(queue),
            best.robot,
            [q[0] for q in queue],
            np.array([q[1] for q in queue]),
            np.array([q[2] for q in queue]),
            np.array([q[3] for q in queue]),
        )
        bus.publish(bus.keys.award(best.robot), award, True)
        if not acks.wait(best.robot, len(queue), ROUND_TIMEOUT_S):
            raise RuntimeError(f"{best.robot} did not acknowledge award {len(queue)}")
        lot_s.append(time.perf_counter() - t0)
        bids_s.append(t1 - t0)
        cpu_s.append(time.process_time() - c0)
        answers.append(len(rnd.bids))
        unanswered += len(robots) - len(rnd.bids)
        progress(len(lot_s), len(floor.tasks))
    return {
        "lots_sold": len(lot_s),
        "lots": len(floor.tasks),
        "allocation": allocation,
        "lot_ms": _quantiles(lot_s),
        "bids_ms": _quantiles(bids_s),
        "coordinator_cpu_ms_per_lot": 1e3 * float(np.mean(cpu_s)) if cpu_s else None,
        "answers_per_round": min(answers, default=0),
        "unanswered": unanswered,
        "rejected": auctioneer.rejected(),
    }


def _quantiles(seconds: list[float]) -> dict[str, float | None]:
    if not seconds:
        return {"median": None, "p95": None, "max": None}
    ms = 1e3 * np.asarray(seconds)
    return {
        "median": float(np.median(ms)),
        "p95": float(np.percentile(ms, 95)),
        "max": float(ms.max()),
    }


def offline(floor: Floor, live: Allocation) -> dict[str, Any]:
    """The baseline: the same auctions in one process (:func:`planners.auction.allocate`), and
    both allocations judged on one travel grid."""
    travel = auction.floor_travel(floor.grid, floor.radius, floor.speed)
    robots = {robot_name(i): auction.Commitment(p[:2]) for i, p in enumerate(floor.poses)}
    t0 = time.perf_counter()
    allocation = auction.allocate(floor.tasks, robots, travel)
    wall = time.perf_counter() - t0
    return {
        "same": allocation == live,
        "ms_per_lot": 1e3 * wall / max(len(floor.tasks), 1),
        "makespan_s": auction.makespan(allocation, floor.tasks, robots, travel),
        "live_makespan_s": auction.makespan(live, floor.tasks, robots, travel),
    }


def run_bench(
    world: str = "home",
    robots: int = 20,
    tasks: int = 500,
    seed: int = 0,
    progress: Any = lambda _done, _total: None,
) -> dict[str, Any]:
    """Sell the tour of ``world``, cut into about ``tasks`` tasks, to ``robots`` bidder
    processes over a router on a free loopback port; the figures (the module docstring)."""
    from fleet.bus import Bus
    from fleet.supervisor.launcher import free_port

    cfg = load_fleet_config()
    floor = make_floor(world, robots, tasks, seed, cfg)
    ctx = mp.get_context("spawn")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    stop, out = ctx.Event(), ctx.Queue()
    ready = [ctx.Event() for _ in range(robots + 1)]
    router = ctx.Process(target=_router_main, args=(endpoint, ready[0], stop), daemon=True)
    router.start()
    names = [robot_name(i) for i in range(robots)]
    procs = [router]
    try:
        if not ready[0].wait(START_TIMEOUT_S):
            raise RuntimeError(f"the router on {endpoint} did not start")
        for i in range(robots):
            args = (endpoint, i, floor, ready[i + 1], stop, out)
            procs.append(ctx.Process(target=_bidder_main, args=args, daemon=True))
            procs[-1].start()
        deadline = time.monotonic() + START_TIMEOUT_S
        for i, ev in enumerate(ready[1:]):
            if not ev.wait(max(deadline - time.monotonic(), 0.0)):
                raise RuntimeError(f"{names[i]} did not start within {START_TIMEOUT_S:.0f} s")
        with Bus("coordinator", "coordinator", [endpoint]) as bus:
            _wait_for_bidders(bus, names)
            live = _sell_all(bus, floor, names, progress)
        stop.set()
        robot_cpu = {}
        for _ in names:
            rid, answered, cpu = out.get(timeout=30.0)
            robot_cpu[rid] = 1e3 * cpu / max(answered, 1)
    finally:
        stop.set()
        for p in procs:
            p.join(10.0)
            if p.is_alive():
                p.kill()
    base = offline(floor, live.pop("allocation"))
    lot_ms = live["lot_ms"]["median"]
    return {
        "world": world,
        "robots": robots,
        "seed": seed,
        **live,
        "robot_cpu_ms_per_answer": statistics.median(robot_cpu.values()),
        "makespan_s": base["live_makespan_s"],
        "offline_ms_per_lot": base["ms_per_lot"],
        "offline_makespan_s": base["makespan_s"],
        "same_allocation_as_offline": base["same"],
        "lot_vs_offline": lot_ms / base["ms_per_lot"] if lot_ms and base["ms_per_lot"] else None,
    }


def _wait_for_bidders(bus: Any, names: list[str]) -> None:
    """Until the router has every robot's session (their liveliness tokens): a round called
    before a robot's subscription reaches the router would go unanswered by it."""
    deadline = time.monotonic() + START_TIMEOUT_S
    want = {bus.keys.alive("robot", r) for r in names}
    while time.monotonic() < deadline:
        replies = bus.session.liveliness().get(bus.keys.alive_all("robot"), timeout=2.0)
        seen = {str(r.ok.key_expr) for r in replies if r.ok is not None}
        if want <= seen:
            time.sleep(0.5)  # their subscriptions follow their tokens
            return
        time.sleep(0.2)
    raise RuntimeError("the robots' sessions did not all reach the router")


def table_lines(result: dict[str, Any]) -> list[str]:
    """The bench's figures as lines for a terminal."""
    lot, bids = result["lot_ms"], result["bids_ms"]
    return [
        f"{Path(result['world']).stem}: {result['robots']} robots, {result['lots']} tasks, "
        f"{result['lots_sold']} sold one lot a round (seed {result['seed']})",
        f"lot, call to acknowledgement: median {lot['median']:.1f} ms, p95 {lot['p95']:.1f}, "
        f"max {lot['max']:.1f}",
        f"  of which the bids: median {bids['median']:.1f} ms, p95 {bids['p95']:.1f}",
        f"coordinator CPU per lot: {result['coordinator_cpu_ms_per_lot']:.1f} ms; "
        f"robot CPU per answer (median robot): {result['robot_cpu_ms_per_answer']:.2f} ms",
        f"answers per round (least): {result['answers_per_round']} of {result['robots']}; "
        f"rejected: {result['rejected'] or 'none'}",
        f"offline, one process: {result['offline_ms_per_lot']:.2f} ms per lot "
        f"(live × {result['lot_vs_offline']:.1f}); makespan live {result['makespan_s']:.1f} s, "
        f"offline {result['offline_makespan_s']:.1f} s; same allocation: "
        f"{result['same_allocation_as_offline']}",
    ]
