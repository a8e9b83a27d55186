"""`fleet bench auction` on a real router: twenty bidder processes, an agent's market each,
buy a home's tour cut into 500 tasks from the real auctioneer, one lot a round. Every lot is
decided, every robot answers every round with one message, and the allocation is the one the
same auctions make in one process."""

from __future__ import annotations

import pytest

from fleet.bench.auction import run_bench


@pytest.mark.integration
@pytest.mark.slow
@pytest.mark.timeout(300)
def test_twenty_bidders_buy_five_hundred_tasks_and_every_lot_is_decided() -> None:
    result = run_bench("home", robots=20, tasks=500, seed=0)
    assert result["lots"] >= 500
    assert result["lots_sold"] == result["lots"]
    # one answer from each robot in every round, none late, malformed or twice
    assert result["answers_per_round"] == 20 and result["unanswered"] == 0
    assert result["rejected"] == {}
    # prices from memory (agents.market) and over the bus change no award
    assert result["same_allocation_as_offline"]
    assert result["makespan_s"] == pytest.approx(result["offline_makespan_s"])
