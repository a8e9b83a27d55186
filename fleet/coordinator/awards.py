"""Each robot's queue on ``coord/award/<robot>``, numbered, and sent again until acknowledged.

An award is a robot's whole queue of won tasks in driving order, each with its ends as the robot
will drive it (:func:`fleet.plan_chain.driven_ends`) and its time. It goes out whenever the
queue changes, numbered one past the robot's last, and again every ``RESEND_S`` until the robot
acknowledges it on ``coord/ack/<robot>``. An agent takes only an award numbered past the last
one it took, so the number is on disk before the award goes out; an acknowledgement numbered
past the coordinator's own (its awards were lost in a restart) makes it number on from the
agent's and send the queue again.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from fleet.coordinator.journal import Journal, Publish
from fleet.plan_chain import driven_ends
from fleet.protocol import Award, AwardAck, Keys

log = logging.getLogger("coordinator")

RESEND_S = 0.5


class Awards:
    """The queues sent, and which robots must have theirs sent again."""

    def __init__(self, journal: Journal, keys: Keys, publish: Publish) -> None:
        self.journal = journal
        self.job = journal.job
        self.keys = keys
        self.publish = publish
        self.sent: dict[str, tuple[str, ...]] = {}
        self.renumbered: set[str] = set()  # robots whose queue goes out again under a new number
        self.last_sent: dict[str, float] = {}

    def resume(self) -> None:
        """A restarted coordinator's robots hold the queues the store has for them."""
        for rid in self.job.robots:
            self.sent[rid] = tuple(t.task.id for t in self.job.queue(rid))

    def send(self) -> None:
        """Send each robot its queue when it changed (or is unacknowledged and due again)."""
        now = time.monotonic()
        for rid, r in self.job.robots.items():
            queue = self.job.queue(rid)
            ids = tuple(t.task.id for t in queue)
            changed = ids != self.sent.get(rid, ()) or rid in self.renumbered
            self.renumbered.discard(rid)
            due = r.acked_seq < r.award_seq and now - self.last_sent.get(rid, 0) > RESEND_S
            if not (changed or due):
                continue
            if changed:
                r.award_seq += 1
                self.sent[rid] = ids
                # a restarted coordinator must number on from here: an agent ignores an award
                # numbered at or below one it has taken
                self.journal.save_robots([r])
            ends = [driven_ends(t.task, t.reverse) for t in queue]
            msg = Award(
                self.journal.clock,
                r.award_seq,
                rid,
                list(ids),
                np.array([e for e, _ in ends], dtype=float).reshape(-1, 2),
                np.array([x for _, x in ends], dtype=float).reshape(-1, 2),
                np.array([t.task.time_s for t in queue], dtype=float),
            )
            self.last_sent[rid] = now
            self.publish(self.keys.award(rid), msg, True)

    def acked(self, rid: str, msg: AwardAck) -> bool:
        """Take ``rid``'s acknowledgement; False if it is not one of a known robot's."""
        r = self.job.robots.get(rid)
        if r is None or msg.robot != rid:
            return False
        if msg.seq <= r.award_seq:
            r.acked_seq = max(r.acked_seq, msg.seq)
        else:
            log.warning(
                "%s acknowledged award %d, past our %d; sending its queue again as %d",
                rid,
                msg.seq,
                r.award_seq,
                msg.seq + 1,
            )
            r.award_seq = msg.seq
            self.renumbered.add(rid)
        return True
