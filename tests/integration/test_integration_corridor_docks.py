"""Traffic both ways through the corridor world's corridor, with batteries: real processes on a
real router, three robots, a dock in each room, `--deconfliction prioritized`. The world's own
starts are all in the left room and a robot sent to charge goes to the dock it is on soonest
(waiting by its room's dock rather than crossing), so crossings both ways at once would be left
to chance; here robot-0 starts in the left room and robot-1 and robot-2 in the right one (the
walls and docks are the world's), and `fleet dock --dock` makes the traffic: at one moment
robot-0 is sent to the right room's dock and robot-2 to the left room's, so each crosses the
corridor against the other, on trips planned together (the corridor is one robot wide: the
plan's order of passage lets one through first while the other waits). A full charge lasts 300 s
of sweeping, so the robots charge on the way home and at the job's end, and rarely before.

The recorded true tracks must show robot-0 crossing left to right and robot-2 right to left,
each between the moment both were sent and its charging on the far dock, with no robot–robot
contact and no robot out of charge. The fleet is stopped (`fleet down`) once both charge: the
rest of the job, and parking at its end, are the battery test's and the unit tests' (a full
job here took two minutes of the suite's time)."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import pytest
import yaml
from fleet_runs import WORLDS, FleetRun, battery_config

# the corridor runs from x = 3 to x = 5 m; a passage is counted from and to 0.5 m beyond its
# ends, so a robot waiting at a mouth for another to come out is in its passage
LEFT_X, RIGHT_X = 2.5, 5.5
# robot-1 starts a metre in front of the right room's dock, facing it; robot-2 in the far corner
STARTS = [[0.9, 1.5, 0.0], [6.6, 1.0, 0.0], [7.55, 2.6, math.pi]]
# robots are sent home this long after the first allocation (sim s; 12 s into an idle run's sim)
SEND_AFTER_AWARD_S = 7.0


def passages(tracks: Path) -> list[tuple[str, str, float, float]]:
    """Each whole passage through the corridor by the true tracks: (robot, "LR" or "RL", sim s
    it entered, sim s it came out on the other side)."""
    side: dict[str, str] = {}
    entered: dict[str, float] = {}
    out = []
    with tracks.open() as f:
        for row in csv.DictReader(f):
            rid, t, x = row["robot"], float(row["sim_s"]), float(row["x"])
            now = "L" if x < LEFT_X else "R" if x > RIGHT_X else None
            if now is None:
                entered.setdefault(rid, t)
                continue
            was = side.get(rid)
            if was is not None and was != now and rid in entered:
                out.append((rid, was + now, entered[rid], t))
            entered.pop(rid, None)
            side[rid] = now
    return out


def crossed(
    found: list[tuple[str, str, float, float]], robot: str, way: str, start: float, end: float
) -> bool:
    """Whether ``robot`` came out of the corridor ``way`` ("LR" or "RL") on the far side
    between sim times ``start`` and ``end`` (it may have been at the near mouth already)."""
    return any(r == robot and w == way and start < t1 <= end for r, w, _, t1 in found)


def test_passages_are_read_from_the_tracks(tmp_path: Path) -> None:
    """The reading itself: one robot goes left to right while another comes back."""
    rows = [(0.0, "a", 2.0), (0.0, "b", 6.0), (5.0, "a", 4.0), (6.0, "b", 4.5)]
    rows += [(10.0, "a", 5.8), (14.0, "b", 2.2), (20.0, "a", 4.5)]
    path = tmp_path / "tracks.csv"
    path.write_text("sim_s,robot,x,y\n" + "".join(f"{t},{r},{x},1.45\n" for t, r, x in rows))
    found = passages(path)
    assert found == [("a", "LR", 5.0, 10.0), ("b", "RL", 6.0, 14.0)]
    assert crossed(found, "a", "LR", 4.0, 10.0) and crossed(found, "b", "RL", 4.0, 15.0)
    assert not crossed(found, "a", "RL", 0.0, 30.0)  # the other way
    assert not crossed(found, "b", "RL", 14.0, 30.0)  # out before
    assert not crossed(found, "a", "LR", 0.0, 9.0)  # not out by then


def _world(path: Path) -> Path:
    data = yaml.safe_load((WORLDS / "corridor.yaml").read_text())
    data["starts"] = STARTS
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.integration
@pytest.mark.slow
@pytest.mark.long
@pytest.mark.timeout(900)
def test_robots_sent_to_each_others_docks_cross_the_corridor_both_ways(tmp_path: Path) -> None:
    config = battery_config(tmp_path / "fleet.yaml", capacity_s=300.0, charge_rate=8.0)
    options = ("--config", str(config), "--deconfliction", "prioritized")
    world = str(_world(tmp_path / "corridor.yaml"))
    run = FleetRun(tmp_path / "run", robots=3, world=world, timeout_s=600.0, options=options)
    tracks = tmp_path / "run" / "tracks.csv"
    clock = run.clock()
    try:
        run.wait_for(lambda: run.first_award() is not None, 180, "the first award")
        at = (run.first_award() or 0.0) + SEND_AFTER_AWARD_S
        run.wait_for(lambda: clock.t >= at, timeout=180, what=f"sim time {at:.1f} s")
        run.verb("dock", "robot-0", "--dock", "1")
        run.verb("dock", "robot-2", "--dock", "0")
        for rid in ("robot-0", "robot-2"):
            run.wait_for(lambda r=rid: run.events("charging", r), 240, f"{rid} charging")
        run.verb("down")
        report = run.finish()
    finally:
        run.cleanup()
    assert run.left == [], f"processes left behind: {run.left}"
    sent = {(e["robot"], e["detail"]): e["sim"] for e in run.events("dock")}
    at = max(
        sent[("robot-0", "sent home by cli: to dock 1")],
        sent[("robot-2", "sent home by cli: to dock 0")],
    )
    found = passages(tracks)
    for rid, way in (("robot-0", "LR"), ("robot-2", "RL")):
        docked = min(
            (e["sim"] for e in run.events("charging", rid) if e["sim"] > at), default=math.inf
        )
        assert crossed(found, rid, way, at, docked), f"{rid} did not cross {way}: {found}"
    assert report["collisions"]["robot_robot"] == 0, run.explained()
    batteries = {rid: r["battery"] for rid, r in report["robots"].items()}
    assert all(b["min_charge"] > 0 for b in batteries.values()), batteries
