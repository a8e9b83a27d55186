"""`fleet bench explore`'s figures: one seed's comparison and the verdict on the targets."""

from __future__ import annotations

from pathlib import Path

from fleet.bench.explore import cleaning_figures, seed_figures, verdict


def _seed(team_s: float, iou: float, walls: float, on_map: float, contacts: int) -> dict:
    team = {"sim_s": team_s, "path_length_m": 60.0, "free_iou": iou, "walls_within": walls}
    alone = {"sim_s": 240.0, "path_length_m": 50.0}
    report = {
        "status": "done",
        "coverage": on_map,
        "repetition": 0.3,
        "makespan_s": 250.0,
        "collisions": {"robot_wall": contacts, "robot_robot": 0},
        "plan": {"floor": "map.yaml"},
    }
    world = dict(report, coverage=0.975, collisions={"robot_wall": 0, "robot_robot": 0})
    return seed_figures(
        team, alone, cleaning_figures(report, Path("m")), cleaning_figures(world, Path("w"))
    )


def test_a_seed_compares_the_team_with_one_robot_and_the_map_with_the_world_file():
    s = _seed(96.0, 0.97, 0.96, 0.97, 0)
    assert s["time_ratio"] == 0.4
    assert s["path_ratio"] == 1.2
    assert s["coverage_gap_points"] == -0.5
    assert s["clean_on_map"]["floor"] == "map.yaml" and s["clean_on_map"]["contacts"] == 0


def test_the_verdict_is_the_worst_seeds():
    good = _seed(96.0, 0.97, 0.96, 0.97, 0)
    v = verdict([good, good])
    assert all(v["met"].values()), v
    slow = _seed(150.0, 0.97, 0.96, 0.97, 0)
    assert not verdict([good, slow])["met"]["time_ratio"]
    assert not verdict([good, _seed(96.0, 0.94, 0.96, 0.97, 0)])["met"]["free_iou"]
    assert not verdict([good, _seed(96.0, 0.97, 0.90, 0.97, 0)])["met"]["walls_within"]
    assert not verdict([good, _seed(96.0, 0.97, 0.96, 0.96, 0)])["met"]["coverage_gap"]
    assert not verdict([good, _seed(96.0, 0.97, 0.96, 0.97, 2)])["met"]["contacts"]
    # a seed whose cleaning left no report meets nothing that needs it
    broken = dict(good, clean_on_map={"status": "no report"})
    broken.pop("coverage_gap_points")
    v = verdict([good, broken])
    assert not v["met"]["coverage_gap"] and not v["met"]["contacts"]
