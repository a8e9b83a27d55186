"""The soak bench's sampling and verdict (fleet.bench.soak), without processes: /proc of this
test's own process, and samples made up to pass or fail each target."""

from __future__ import annotations

import os
import sqlite3
from pathlib import Path

from fleet.bench.soak import (
    RESULT_FILE,
    Sample,
    Targets,
    dir_bytes,
    jobs_finished,
    open_files,
    rss_kb,
    table_lines,
    verdict,
)

TARGETS = Targets(rss_growth=0.05, dir_mb_per_h=50.0, warmup_s=600.0)


def _samples(
    rss: list[int],
    fds: list[int] | None = None,
    mb: list[float] | None = None,
    pid: int = 7,
    every: float = 300.0,
) -> list[Sample]:
    """One process, ``p``, sampled every ``every`` sim s from then on (the warm-up ends at
    600)."""
    n = len(rss)
    fds = fds or [20] * n
    mb = mb or [10.0] * n
    return [
        Sample(
            every * (i + 1), every * (i + 1) / 2, {"p": pid}, {"p": r}, {"p": f}, int(m * 1e6), i
        )
        for i, (r, f, m) in enumerate(zip(rss, fds, mb, strict=True))
    ]


def test_this_process_has_memory_and_open_files_and_a_gone_one_has_none() -> None:
    assert rss_kb(os.getpid()) > 1000
    assert open_files(os.getpid()) >= 3
    gone = 2**22 + 1  # above Linux's pid_max
    assert rss_kb(gone) is None and open_files(gone) is None


def test_the_run_dir_size_counts_every_file_but_the_result(tmp_path: Path) -> None:
    (tmp_path / "a.log").write_bytes(b"x" * 1000)
    (tmp_path / "robot-0").mkdir()
    (tmp_path / "robot-0" / "map.npz").write_bytes(b"x" * 500)
    (tmp_path / RESULT_FILE).write_bytes(b"x" * 10_000)
    assert dir_bytes(tmp_path) == 1500


def test_jobs_finished_are_the_coordinators_finished_events(tmp_path: Path) -> None:
    state = tmp_path / "coordinator.sqlite"
    assert jobs_finished(state) == 0
    db = sqlite3.connect(state)
    db.execute("CREATE TABLE events (seq INTEGER PRIMARY KEY, kind TEXT)")
    db.executemany("INSERT INTO events (kind) VALUES (?)", [("finished",), ("done",)] * 3)
    db.commit()
    db.close()
    assert jobs_finished(state) == 3


def test_flat_memory_and_files_and_a_slow_growing_dir_pass() -> None:
    # memory climbs in the warm-up, then within 5 %
    v = verdict(_samples([100_000, 150_000, 151_000, 152_000, 154_000]), TARGETS)
    p = v["processes"]["p"]
    assert p["judged"] and p["ok"], p
    # levels: the medians of the samples 300 s past the warm-up and 300 s before the end
    assert p["rss_mb_at_warmup"] == round(150_500 / 1024, 1)
    assert p["rss_mb_at_end"] == round(153_000 / 1024, 1)
    assert p["rss_growth"] == round(153_000 / 150_500 - 1, 4)
    assert p["rss_growth_last_sample"] == round(154_000 / 150_000 - 1, 4)
    assert v["run_dir"]["ok"] and v["ok"]


def test_memory_growing_past_5_percent_after_the_warm_up_fails() -> None:
    v = verdict(_samples([150_000, 150_000, 154_000, 158_000, 162_000, 166_000]), TARGETS)
    assert v["processes"]["p"]["rss_growth"] > 0.05
    assert not v["processes"]["p"]["ok"] and not v["ok"]


def test_a_spike_in_the_last_sample_is_not_growth_but_a_rising_level_is() -> None:
    """Sampled every 60 s: a process that holds 15 % more for one sample and gives it back is
    flat; one whose level rises by 6 % over its last five minutes is not."""
    flat = [100_000] * 9 + [150_000, 151_000, 150_000, 149_000, 150_000] * 6
    spike = verdict(_samples([*flat, 172_000], every=60.0), TARGETS)["processes"]["p"]
    assert spike["ok"] and spike["rss_growth"] <= 0.01, spike
    assert spike["rss_growth_last_sample"] > 0.14
    rising = verdict(_samples([*flat, *[159_000] * 5], every=60.0), TARGETS)["processes"]["p"]
    assert not rising["ok"] and rising["rss_growth"] > 0.05, rising


def test_open_files_that_rise_in_the_later_half_fail_and_ones_that_come_and_go_pass() -> None:
    flat = [150_000] * 7
    leak = verdict(_samples(flat, fds=[20, 20, 20, 21, 22, 23, 24]), TARGETS)
    assert leak["processes"]["p"]["fds_grew"] and not leak["ok"]
    wobble = verdict(_samples(flat, fds=[20, 22, 20, 21, 22, 20, 22]), TARGETS)
    p = wobble["processes"]["p"]
    assert not p["fds_grew"] and p["ok"] and (p["fds_min"], p["fds_max"]) == (20, 22)


def test_a_run_dir_growing_faster_than_the_target_fails() -> None:
    # 10 MB per 300 sim s past the warm-up: 120 MB per sim hour
    v = verdict(_samples([150_000] * 5, mb=[5.0, 10.0, 20.0, 30.0, 40.0]), TARGETS)
    assert v["run_dir"]["mb_per_sim_h"] == 120.0
    assert not v["run_dir"]["ok"] and not v["ok"]


def test_a_restarted_process_is_named_and_judged_on_its_samples_since() -> None:
    before = _samples([300_000] * 3, pid=7)
    after = _samples([150_000] * 4, pid=8)[3:]
    after += [
        Sample(1500.0, 750.0, {"p": 8}, {"p": 151_000}, {"p": 20}, 10_000_000, 5),
        Sample(1800.0, 900.0, {"p": 8}, {"p": 152_000}, {"p": 20}, 10_000_000, 6),
    ]
    p = verdict(before + after, TARGETS)["processes"]["p"]
    assert p["restarted"] and p["ok"] and p["rss_mb_at_warmup"] == round(150_500 / 1024, 1)


def test_a_run_too_short_to_judge_does_not_pass() -> None:
    v = verdict(_samples([150_000, 150_000]), TARGETS)
    assert not v["processes"]["p"]["judged"] and not v["ok"]


def test_the_table_has_a_row_per_process_and_the_verdict() -> None:
    samples = _samples([150_000, 150_000, 151_000, 152_000])
    result = {
        "robots": 1,
        "world": "small",
        "sim_s": 1200.0,
        "speed": 0.0,
        "stopped": "",
        "verdict": verdict(samples, TARGETS),
    }
    lines = table_lines(result)
    assert any(line.startswith("p ") and line.endswith("ok") for line in lines), lines
    assert lines[-1] == "verdict: pass"
