"""The messages a job has dropped: those malformed or implausible on the bus, counted by this
coordinator and by the coordinators before it in the same job (a resumed job's counters), and
the bids its auctioneer refused as malformed or from a robot not in the market (late and
duplicate bids are no one's fault). They go out in ``coord/state`` and to the store's meta."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from fleet.bus import Bus


@dataclass(frozen=True)
class Dropped:
    """The counts of one job's dropped messages, on ``bus`` and ``before`` it (malformed,
    implausible)."""

    bus: Bus
    before: tuple[int, int] = (0, 0)

    @classmethod
    def resumed(cls, bus: Bus, meta: Mapping[str, object]) -> Dropped:
        """The counts of a job resumed with the counters ``meta`` (``dropped``: those of the
        coordinators before this one), heard on ``bus`` from now on."""
        before = meta.get("dropped")
        before = before if isinstance(before, dict) else {}
        return cls(bus, (int(before.get("malformed", 0)), int(before.get("implausible", 0))))

    def on_bus(self) -> tuple[int, int]:
        """(malformed, implausible) messages dropped on the bus in this job, by this process
        and the coordinators before it."""
        malformed, implausible = self.bus.dropped()
        return malformed + self.before[0], implausible + self.before[1]

    def in_job(self, rejected: Mapping[str, int]) -> tuple[int, int]:
        """(malformed, implausible) messages dropped in this job: those on the bus, and the
        bids ``rejected`` (the auctioneer's refusals by reason) that were malformed or from a
        robot not in the market."""
        malformed, implausible = self.on_bus()
        refused = rejected.get("malformed", 0) + rejected.get("not in the market", 0)
        return malformed, implausible + refused
