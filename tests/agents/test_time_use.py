"""Where a robot's time goes: each control step's kind, and the sums in report.json."""

from __future__ import annotations

import dataclasses

import numpy as np

from agents.follow.state import FollowState
from agents.time_use import step_kind
from fleet.protocol import TIME_KINDS, RobotStatus, decode, encode
from fleet.report.summary import time_use_of

PATH = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]])


def test_each_step_is_put_in_the_kind_the_follower_was_in() -> None:
    at = FollowState(PATH, index=2)
    assert step_kind(at, at, sweep_from=1) == "sweep"
    assert step_kind(at, at, sweep_from=2) == "transit"  # still driving to the sweep's start
    assert step_kind(at, dataclasses.replace(at, aligning=True), 1) == "turn"
    assert step_kind(at, dataclasses.replace(at, escape_m=0.1, aligning=True), 1) == "escape"
    assert step_kind(at, dataclasses.replace(at, yielded_s=0.1), 1) == "yield"
    assert step_kind(None, None, 0) == "idle"
    assert step_kind(at, FollowState(PATH, index=4), 1) == "idle"  # the plan just ended


def test_reported_sums_reach_the_report_by_name() -> None:
    seconds = np.arange(len(TIME_KINDS), dtype=float) * 1.25
    status = RobotStatus(1.0, "driving", "t00", 0.5, 2, 4, 1.0, time_s=seconds)
    again = decode(encode(status), RobotStatus)
    assert time_use_of(again) == dict(zip(TIME_KINDS, np.round(seconds, 1), strict=True))
    assert time_use_of(RobotStatus(1.0, "driving", "t00", 0.5, 2, 4, 1.0)) is None
