"""MovingAI .map/.scen and libMultiRobotPlanning YAML: parsing, errors, round trips."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from planners.mapf import MapfInstance, solve, validate
from planners.mapf.movingai import (
    FormatError,
    load_instance,
    read_map,
    read_scen,
    write_map,
    write_scen,
)
from planners.mapf.yaml_format import (
    read_instance,
    result_to_mapping,
    schedule_from_mapping,
    write_yaml,
)

TERRAIN_MAP = "type octile\nheight 2\nwidth 7\nmap\n.GS@OTW\n@@@.SG.\n"


def test_every_terrain_letter(tmp_path: Path) -> None:
    (tmp_path / "t.map").write_text(TERRAIN_MAP)
    free = read_map(tmp_path / "t.map")
    assert free.tolist() == [
        [True, True, True, False, False, False, False],
        [False, False, False, True, True, True, True],
    ]


def test_crlf_line_endings(tmp_path: Path) -> None:
    (tmp_path / "t.map").write_bytes(TERRAIN_MAP.replace("\n", "\r\n").encode())
    scen = "version 1\r\n0\tt.map\t7\t2\t0\t0\t6\t1\t7.0\r\n"
    (tmp_path / "t.scen").write_bytes(scen.encode())
    instance = load_instance(tmp_path / "t.map", tmp_path / "t.scen")
    assert instance.shape == (2, 7)
    assert instance.starts == ((0, 0),)
    assert instance.goals == ((1, 6),)


def test_unknown_terrain_names_file_and_line(tmp_path: Path) -> None:
    (tmp_path / "bad.map").write_text("type octile\nheight 2\nwidth 3\nmap\n...\n.x.\n")
    with pytest.raises(FormatError, match=r"bad\.map:6: unknown terrain 'x' in column 2"):
        read_map(tmp_path / "bad.map")


def test_short_row_and_missing_header_are_errors(tmp_path: Path) -> None:
    (tmp_path / "a.map").write_text("type octile\nheight 2\nwidth 3\nmap\n...\n..\n")
    with pytest.raises(FormatError, match=r"a\.map:6: 2 characters"):
        read_map(tmp_path / "a.map")
    (tmp_path / "b.map").write_text("type octile\nwidth 3\nmap\n...\n")
    with pytest.raises(FormatError, match="height"):
        read_map(tmp_path / "b.map")


def test_scen_whose_map_name_differs_from_the_file(tmp_path: Path) -> None:
    (tmp_path / "mine.map").write_text(
        "type octile\nheight 3\nwidth 7\nmap\n.GS@OTW\n.......\n@@@.SG.\n"
    )
    lines = [
        "version 1",
        "3\tsomewhere/else/original-name.map\t7\t3\t1\t0\t4\t2\t3.82842712",
        "7\tsomewhere/else/original-name.map\t7\t3\t0\t0\t6\t2\t6.82842712",
    ]
    (tmp_path / "x.scen").write_text("\n".join(lines) + "\n")
    entries = read_scen(tmp_path / "x.scen")
    assert entries[0].map_name == "somewhere/else/original-name.map"
    assert entries[0].bucket == 3
    assert entries[0].start == (0, 1)  # (row = y, col = x)
    assert entries[0].goal == (2, 4)
    assert entries[1].optimal_length == pytest.approx(6.82842712)
    one = load_instance(tmp_path / "mine.map", tmp_path / "x.scen", 1)
    assert one.num_agents == 1
    # column 9 is octile (3.83); the 4-connected optimum is 5
    result = solve(one, "cbs")
    assert result.soc == 5


def test_scen_errors(tmp_path: Path) -> None:
    (tmp_path / "m.map").write_text(TERRAIN_MAP)
    (tmp_path / "wrong.scen").write_text("version 1\n0\tm.map\t9\t9\t0\t0\t1\t0\t1\n")
    with pytest.raises(FormatError, match="9x9 map"):
        load_instance(tmp_path / "m.map", tmp_path / "wrong.scen")
    (tmp_path / "short.scen").write_text("version 1\n0\tm.map\t7\t2\t0\t0\n")
    with pytest.raises(FormatError, match=r"short\.scen:2: expected 9"):
        read_scen(tmp_path / "short.scen")
    (tmp_path / "ok.scen").write_text("version 1\n0\tm.map\t7\t2\t0\t0\t1\t0\t1\n")
    with pytest.raises(FormatError, match="asked for 5 agents"):
        load_instance(tmp_path / "m.map", tmp_path / "ok.scen", 5)


def test_movingai_round_trip(tmp_path: Path) -> None:
    from planners.mapf.generate import random_instance, random_map

    free = random_map(9, 13, 0.2, 4)
    instance = random_instance(free, 6, 1)
    write_map(tmp_path / "r.map", free)
    write_scen(tmp_path / "r.scen", "r.map", instance)
    back = load_instance(tmp_path / "r.map", tmp_path / "r.scen", 4)
    assert np.array_equal(back.free, free)
    assert back.starts == instance.starts[:4]
    assert back.goals == instance.goals[:4]


INSTANCE_YAML = """
map:
  dimensions: [3, 3]
  obstacles:
  - [1, 1]
agents:
- {name: left, start: [0, 0], goal: [2, 2]}
- {name: right, start: [2, 0], goal: [0, 2]}
"""


def test_yaml_instance_and_schedule(tmp_path: Path) -> None:
    (tmp_path / "in.yaml").write_text(INSTANCE_YAML)
    instance = read_instance(tmp_path / "in.yaml")
    assert instance.names == ("left", "right")
    assert instance.shape == (3, 3)
    assert not instance.free[1, 1]
    assert instance.free.sum() == 8
    assert instance.starts == ((0, 0), (0, 2))
    assert instance.goals == ((2, 2), (2, 0))
    result = solve(instance, "cbs")
    assert result.status == "success"
    write_yaml(tmp_path / "out.yaml", result_to_mapping(instance, result))
    data = yaml.safe_load((tmp_path / "out.yaml").read_text())
    stats = data["statistics"]
    assert set(stats) == {"cost", "makespan", "runtime", "highLevelExpanded", "lowLevelExpanded"}
    assert stats["cost"] == result.soc
    assert data["schedule"]["left"][0] == {"x": 0, "y": 0, "t": 0}
    paths = schedule_from_mapping(instance, data)
    report = validate(instance, paths)
    assert report.valid
    assert report.soc == stats["cost"]


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("agents: []\n", "map: missing"),
        ("map: {dimensions: [3]}\nagents: []\n", r"map\.dimensions: expected \[x, y\]"),
        (
            "map: {dimensions: [2, 2], obstacles: [[5, 0]]}\n"
            "agents: [{start: [0, 0], goal: [1, 1]}]\n",
            r"obstacles\[0\].*outside",
        ),
        ("map: {dimensions: [2, 2]}\nagents: [{name: a, start: [0, 0]}]\n", r"agents\[0\]\.goal"),
    ],
)
def test_yaml_errors_name_the_field(tmp_path: Path, text: str, match: str) -> None:
    (tmp_path / "bad.yaml").write_text(text)
    with pytest.raises(FormatError, match=match):
        read_instance(tmp_path / "bad.yaml")


def test_instance_names_default() -> None:
    instance = MapfInstance(np.ones((1, 2), bool), ((0, 0),), ((0, 1),))
    assert instance.names == ("agent0",)
