"""The coordinator's ``--loop``: when a job finishes, the next starts on the same floor (a long
run of one job, as ``fleet bench soak`` makes)."""

from __future__ import annotations

import threading

from fleet.coordinator.market import Market
from fleet.coordinator.planning import TaskPlanner


def next_job(market: Market, planner: TaskPlanner, lock: threading.RLock) -> str:
    """Start the next job; its phase (``auction``). The floor's tasks are planned again, all
    open; the old job's tasks, plans and remainders leave memory and the store (its events and
    bids stay); the robots, their award numbers and the plan numbers carry on; lost robots'
    bodies are planned round again; and the whole floor goes on sale as a first allocation
    (one region per robot in the market)."""
    tasks = planner.tasks()
    with lock:
        journal = market.journal
        market.job.start_over(tasks)
        journal.clear_job()
        market.dispatcher.start_over()
        market.progress.clear()
        market.lost_at.clear()
        market.region_sale = []
        market.version += 1
        journal.save_tasks(*market.job.tasks)
        for body in list(market.bodies):
            market.plan_around_bodies(body)
        market.need_auction = True
        market.wake.set()
        journal.event("planned", "", "", f"{len(tasks)} tasks: the job again")
        journal.set_meta(phase="auction")
    return "auction"
