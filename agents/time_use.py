"""Where a robot's time goes, one control step at a time.

Each control step of the path follower (:func:`agents.follow.motion.follow_step`) is put in
one of ``fleet.protocol.TIME_KINDS`` by the follower's state before and after it, so a run's
makespan splits into time spent sweeping, driving beside a wall under the wall follower (edge), in
transit to a task, turning in place, giving way to a peer, escaping a dead end, and idle (no
plan, or its plan finished). The agent sums them and reports the sums in its status; ``fleet
up`` puts them in report.json.
"""

from __future__ import annotations

from agents.follow.state import FollowState


def step_kind(before: FollowState | None, after: FollowState | None, sweep_from: int) -> str:
    """The kind of one control step that took the follower from ``before`` to ``after``;
    waypoints up to ``sweep_from`` (the first of the plan's sweep) are the transit."""
    if before is None or after is None or after.done:
        return "idle"
    if after.escape_m > 0:
        return "escape"
    if after.aligning:
        return "turn"
    if after.yielded_s > before.yielded_s:
        return "yield"
    if after.edge_side:
        return "edge"
    if after.index <= sweep_from:
        return "transit"
    return "sweep"
