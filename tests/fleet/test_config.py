"""The configuration loader: errors name the file and the dotted field; unknown fields get a
hint."""

from __future__ import annotations

import copy
import dataclasses
import typing
from pathlib import Path

import pytest
import yaml
from robots import ROBOT

from fleet.config import ConfigError, from_mapping
from fleet.params import REMOVED, FleetConfig, default_config_path, load_fleet_config
from fleet.world import load_world

SECTIONS = typing.get_type_hints(FleetConfig)
DEFAULT_SECTIONS = yaml.safe_load(default_config_path().read_text())


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _config_error(path: Path) -> str:
    with pytest.raises(ConfigError) as info:
        load_fleet_config(path)
    return str(info.value)


def _with(path: Path, section: str, field: str, value: object) -> Path:
    """The built-in fleet.yaml with ``section.field`` set to ``value``, written to ``path``."""
    data = copy.deepcopy(DEFAULT_SECTIONS)
    data[section][field] = value
    return _write(path, yaml.safe_dump(data))


def _typo(name: str) -> str:
    """``name`` with its last two letters swapped: a typo difflib should see through."""
    return name[:-2] + name[-1] + name[-2]


@pytest.mark.parametrize("section", SECTIONS)
def test_a_misspelt_field_of_every_section_gets_a_did_you_mean_hint(
    tmp_path: Path, section: str
) -> None:
    field = max((f.name for f in dataclasses.fields(SECTIONS[section])), key=len)
    path = _with(tmp_path / "fleet.yaml", section, _typo(field), 1)
    msg = _config_error(path)
    assert msg.startswith(f"{path}: {section}.{_typo(field)}: unknown field"), msg
    assert f"did you mean {field!r}?" in msg, msg


@pytest.mark.parametrize("field", ["search_window_min_xy", "search_window_min_theta"])
def test_a_tracking_window_floor_above_its_cap_is_refused(tmp_path: Path, field: str) -> None:
    path = _with(tmp_path / "fleet.yaml", "slam", field, 0.3)
    msg = _config_error(path)
    assert str(path) in msg and field in msg and "floor above its cap" in msg, msg


@pytest.mark.parametrize(("value", "why"), [(-0.1, "within [0, 0.9)"), (0.9, "within [0, 0.9)")])
def test_a_lane_overlap_the_planner_cannot_plan_is_refused_at_load(
    tmp_path: Path, value: float, why: str
) -> None:
    path = _with(tmp_path / "fleet.yaml", "coordinator", "lane_overlap", value)
    msg = _config_error(path)
    assert str(path) in msg and "lane_overlap" in msg and why in msg, msg
    path = _with(tmp_path / "fleet.yaml", "coordinator", "wall_clearance", -0.01)
    assert "wall_clearance must be >= 0" in _config_error(path)


def test_a_misspelt_section_gets_a_hint(tmp_path: Path) -> None:
    path = _write(tmp_path / "fleet.yaml", yaml.safe_dump({"wall_folow": {"speed": 0.1}}))
    msg = _config_error(path)
    assert "wall_folow: unknown field; did you mean 'wall_follow'?" in msg, msg


def test_an_unknown_field_like_no_known_one_gets_no_hint(tmp_path: Path) -> None:
    msg = _config_error(_with(tmp_path / "fleet.yaml", "lidar", "colour", "blue"))
    assert "lidar.colour: unknown field (known: beams," in msg, msg
    assert "did you mean" not in msg


def test_a_mistyped_field_is_named_after_the_file(tmp_path: Path) -> None:
    path = _with(tmp_path / "fleet.yaml", "sim", "physics_hz", "fast")
    assert _config_error(path).startswith(f"{path}: sim.physics_hz: expected a number")


@pytest.mark.parametrize(
    ("text", "field", "hint"),
    [
        ("walls:\n  - [0, 0, 3, 0]\nstart: []\n", "start", "starts"),
        (
            "walls:\n  - [0, 0, 3, 0]\nfurniture:\n  - {center: [1, 1], size: [1, 1], agnle: 3}\n",
            "furniture[0].agnle",
            "angle",
        ),
    ],
)
def test_world_files_get_the_hint_too(tmp_path: Path, text: str, field: str, hint: str) -> None:
    path = _write(tmp_path / "world.yaml", text)
    with pytest.raises(ConfigError) as info:
        load_world(path)
    assert f"{path}: {field}: unknown field; did you mean {hint!r}?" in str(info.value)


def _numeric_fields() -> list[tuple[str, str]]:
    out = []
    for section, cls in SECTIONS.items():
        hints = typing.get_type_hints(cls)
        out += [(section, f.name) for f in dataclasses.fields(cls) if hints[f.name] in (int, float)]
    return out


@pytest.mark.parametrize("value", [0, -1])
@pytest.mark.parametrize(("section", "field"), _numeric_fields())
def test_a_field_refused_for_its_sign_is_named(section: str, field: str, value: int) -> None:
    data = copy.deepcopy(DEFAULT_SECTIONS)
    data[section][field] = value
    try:
        from_mapping(FleetConfig, data, "fleet.yaml")
    except ConfigError as e:
        assert str(e).startswith(f"fleet.yaml: {section}") and field in str(e), str(e)


# configs/fleet.yaml's first line says what its sections show
SHOWS_EVERY_FIELD = "missing ones take the defaults shown here"


def test_fleet_yaml_shows_the_code_defaults() -> None:
    """A field in configs/fleet.yaml holds its dataclass's default: every run uses the file, a
    test or a tool that builds a section in code gets the default, and they must agree. As the
    file says it shows the defaults, it leaves no field out either."""
    text = default_config_path().read_text()
    shown = yaml.safe_load(text)
    every = SHOWS_EVERY_FIELD in text.splitlines()[0]
    wrong = []
    for section, cls in SECTIONS.items():
        values = shown.get(section) or {}
        for f in dataclasses.fields(cls):
            default = f.default is not dataclasses.MISSING
            if f.name not in values:
                if every:
                    wrong.append(f"{section}.{f.name}: missing")
            elif default and values[f.name] != f.default:
                wrong.append(f"{section}.{f.name}: {values[f.name]!r}, the code {f.default!r}")
    assert not wrong, "\n".join(wrong)


def test_the_robot_must_be_described(tmp_path: Path) -> None:
    """robot: has no defaults: a config without it, or without one of its fields, is refused."""
    path = _write(tmp_path / "fleet.yaml", "lidar:\n  beams: 90\n")
    assert _config_error(path) == f"{path}: robot: required field is missing"
    robot = dict(DEFAULT_SECTIONS["robot"])
    del robot["acc_lim_theta"]
    path = _write(tmp_path / "fleet.yaml", yaml.safe_dump({"robot": robot}))
    assert _config_error(path) == f"{path}: robot.acc_lim_theta: required field is missing"
    robot = DEFAULT_SECTIONS["robot"] | {"cleaning_width": 0.5}
    path = _write(tmp_path / "fleet.yaml", yaml.safe_dump({"robot": robot}))
    assert "robot: cleaning_width must not exceed the robot diameter" in _config_error(path)


def test_the_tests_robot_is_the_fleets() -> None:
    assert load_fleet_config().robot == ROBOT


# the fields that copied the robot's numbers, and where they live now; listed here rather than
# read from fleet.params.MOVED_TO_ROBOT, which an emptied table would make an empty test
MOVED = [
    ("dwa", "max_vel_x", "max_vel_x"),
    ("dwa", "max_vel_theta", "max_vel_theta"),
    ("dwa", "acc_lim_x", "acc_lim_x"),
    ("dwa", "acc_lim_theta", "acc_lim_theta"),
    ("coverage", "robot_radius", "radius"),
    ("coverage", "cleaning_width", "cleaning_width"),
    ("coverage", "max_speed", "max_vel_x"),
    ("coverage", "max_accel", "acc_lim_x"),
    ("coverage", "max_turn_rate", "max_vel_theta"),
    ("coverage", "max_turn_accel", "acc_lim_theta"),
]


@pytest.mark.parametrize(("section", "field", "home"), MOVED)
def test_an_old_config_with_a_copy_of_the_robot_is_refused(
    tmp_path: Path, section: str, field: str, home: str
) -> None:
    """The robot's numbers moved to robot:; an old config that still has them elsewhere is told
    where they live now instead of keeping a copy that could disagree."""
    path = _with(tmp_path / "fleet.yaml", section, field, 0.5)
    assert _config_error(path) == (
        f"{path}: {section}.{field}: the robot's size and limits live in robot: "
        f"(robot.{home}); remove {section}.{field}"
    )


@pytest.mark.parametrize(
    ("section", "field", "value"),
    [
        ("agent", "peer_margin", 0.0),
        ("coordinator", "first_regions", "tour"),
        ("coordinator", "sweep_freed_floor", True),
        ("coordinator", "map_changes", True),
        ("coverage", "method", "bcd"),
        ("coverage", "return_strips", True),
    ],
)
def test_an_old_config_with_a_removed_option_is_refused_naming_it(
    tmp_path: Path, section: str, field: str, value: object
) -> None:
    path = _with(tmp_path / "fleet.yaml", section, field, value)
    assert _config_error(path) == (
        f"{path}: {section}.{field}: no longer an option (the code always does what its "
        f"default did); remove {section}.{field}"
    )


def test_no_removed_option_is_a_field_again() -> None:
    cfg = load_fleet_config()
    for section, removed in REMOVED.items():
        fields = {f.name for f in dataclasses.fields(getattr(cfg, section))}
        assert not fields & set(removed), (section, fields & set(removed))


def test_dwa_may_not_sample_faster_than_the_robot_drives(tmp_path: Path) -> None:
    path = _with(tmp_path / "fleet.yaml", "dwa", "min_vel_x", 0.6)
    msg = _config_error(path)
    assert "dwa.min_vel_x (0.6) must not exceed robot.max_vel_x (0.5)" in msg, msg


@pytest.mark.parametrize(
    ("field", "value", "says"),
    [
        ("map_change_confidence", 0.5, "must be within (0.5, 1)"),
        ("map_change_confidence", 1.0, "must be within (0.5, 1)"),
        ("map_change_min_size_m", 0.0, "must be > 0"),
        ("map_change_wall_margin_m", -0.1, "must be > 0"),
        ("map_change_robot_clear_m", 0.0, "must be > 0"),
    ],
)
def test_what_counts_as_furniture_moved_is_checked_naming_the_field(
    tmp_path: Path, field: str, value: object, says: str
) -> None:
    path = _with(tmp_path / "fleet.yaml", "coordinator", field, value)
    msg = _config_error(path)
    assert "coordinator" in msg and field in msg and says in msg, msg


@pytest.mark.parametrize(
    ("field", "value"), [("gain_lateral", -2.0), ("lateral_acc", 0.0), ("clear_ahead", -0.1)]
)
def test_tracker_parameters_that_cannot_work_are_refused_at_load(
    tmp_path: Path, field: str, value: float
) -> None:
    path = _with(tmp_path / "fleet.yaml", "tracker", field, value)
    msg = _config_error(path)
    assert msg.startswith(f"{path}: tracker") and field in msg, msg
