"""The report pictures drawn again from a stored run (tests/data/run_small: two robots on the
small world, as `fleet up` wrote it): legends and robot ids in them, the scale bar's length in
pixels, each robot's colour, and `fleet report` on missing or damaged run dirs."""

from __future__ import annotations

import json
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import matplotlib.colors
import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

from fleet.cli import app
from fleet.colours import robot_colour
from fleet.report.figures import (
    BLOCKED_COLOUR,
    SCALE_BAR_COLOUR,
    SIDE_COLOUR,
    floor_rgb,
    map_figure,
    render_report,
    swept_over_time,
)
from fleet.report.summary import GRID_FILE, REPORT_FILE, TRACKS_FILE, load_run

STORED = Path(__file__).resolve().parents[1] / "data" / "run_small"
SVG = "{http://www.w3.org/2000/svg}"
ROBOTS = ("robot-0", "robot-1")


@pytest.fixture
def run_dir(tmp_path: Path) -> Path:
    d = tmp_path / "run"
    shutil.copytree(STORED, d)
    return d


def _rgb(hex_colour: str) -> tuple[int, int, int]:
    return tuple(int(hex_colour[i : i + 2], 16) for i in (1, 3, 5))  # type: ignore[return-value]


def _longest_run(mask: np.ndarray) -> int:
    """The longest horizontal run of True pixels in any row."""
    best = 0
    for row in mask:
        padded = np.concatenate(([0], row.astype(np.int8), [0]))
        edges = np.flatnonzero(np.diff(padded))
        if len(edges):
            best = max(best, int((edges[1::2] - edges[::2]).max()))
    return best


def _texts(svg: Path, gid: str) -> list[str]:
    """Every text inside the SVG element with id ``gid``."""
    root = ET.parse(svg).getroot()
    node = next((e for e in root.iter() if e.get("id") == gid), None)
    assert node is not None, f"no element {gid!r} in {svg}"
    return ["".join(t.itertext()) for t in node.iter(f"{SVG}text")]


def test_the_map_has_a_legend_with_every_robot_and_each_robot_is_labelled_with_its_id(
    run_dir: Path,
) -> None:
    written = render_report(load_run(run_dir))
    assert {p.name for p in written} == {"report.png", "report.svg", "coverage.png", "coverage.svg"}
    legend = " | ".join(_texts(run_dir / "report.svg", "legend"))
    for rid in ROBOTS:
        assert rid in legend
        assert _texts(run_dir / "report.svg", f"label-{rid}") == [rid]
    assert "missed" in legend and "cleaned once" in legend and "4+" in legend
    assert "lost there" not in legend
    svg_text = (run_dir / "report.svg").read_text()
    assert "coverage 97.8 %" in svg_text and "makespan" in svg_text


def test_the_scale_bar_is_as_long_in_pixels_as_its_metres_on_the_floor(run_dir: Path) -> None:
    data = load_run(run_dir)
    fig, bar_m = map_figure(data)
    png = run_dir / "map.png"
    fig.savefig(png)
    pixels = np.asarray(Image.open(png).convert("RGB"))
    # the floor's outer wall row spans the whole grid: its run of wall pixels is the floor width
    floor_px = _longest_run((pixels == _rgb(BLOCKED_COLOUR)).all(axis=2))
    floor_m = data.visits.shape[1] * data.resolution
    bar_px = _longest_run((pixels == _rgb(SCALE_BAR_COLOUR)).all(axis=2))
    assert bar_m == 1.0
    assert floor_px > 300
    assert bar_px == pytest.approx(bar_m * floor_px / floor_m, abs=2)


def test_each_track_is_drawn_in_its_robots_colour(run_dir: Path) -> None:
    render_report(load_run(run_dir))
    pixels = np.asarray(Image.open(run_dir / "report.png").convert("RGB")).astype(int)
    for rid in ROBOTS:
        near = (np.abs(pixels - _rgb(robot_colour(rid))).sum(axis=2) <= 6).sum()
        assert near > 500, f"{rid}'s colour {robot_colour(rid)} is hardly in the picture"


def test_a_lost_robot_is_marked_on_both_pictures_and_each_robots_share_grows(run_dir: Path) -> None:
    report = json.loads((run_dir / REPORT_FILE).read_text())
    report["events"].append(
        {"wall": 0.0, "sim": 60.0, "kind": "lost", "robot": "robot-1", "task": "", "detail": ""}
    )
    (run_dir / REPORT_FILE).write_text(json.dumps(report))
    data = load_run(run_dir)
    render_report(data)
    legend = _texts(run_dir / "coverage.svg", "legend")
    assert "lost" in legend and "joined" in legend
    assert "lost there" in _texts(run_dir / "report.svg", "legend")
    assert any("robot-0" in t for t in legend) and any("robot-1" in t for t in legend)
    shares = {rid: swept_over_time(data, rid)[1] for rid in ROBOTS}
    for share in shares.values():
        assert np.all(np.diff(share) >= 0) and 0.3 < share[-1] < 0.7
    # the two robots' own shares overlap a little and add up to about the fleet's coverage
    assert sum(s[-1] for s in shares.values()) == pytest.approx(data.report["coverage"], abs=0.15)


def test_fleet_report_draws_again_and_prints_the_figures(run_dir: Path) -> None:
    result = CliRunner().invoke(app, ["report", str(run_dir)])
    assert result.exit_code == 0, result.output
    assert "coverage 97.8 %" in result.output
    assert (run_dir / "report.png").stat().st_size > 10_000


@pytest.mark.parametrize(
    ("damage", "named"),
    [
        (lambda d: shutil.rmtree(d), "no such run dir"),
        (lambda d: (d / GRID_FILE).unlink(), GRID_FILE),
        (lambda d: (d / GRID_FILE).write_bytes(b"not a zip"), GRID_FILE),
        (lambda d: (d / REPORT_FILE).write_text('{"status": "done",'), REPORT_FILE),
        (lambda d: (d / REPORT_FILE).write_text('{"status": "done"}'), "missing field coverage"),
        (lambda d: (d / TRACKS_FILE).write_text("sim_s,robot,x,y\n1.0,robot-0,x,2\n"), ":2"),
        (lambda d: (d / TRACKS_FILE).write_text("t,x\n"), TRACKS_FILE),
    ],
)
def test_fleet_report_on_a_missing_or_damaged_run_dir_names_the_file(
    run_dir: Path, damage, named: str
) -> None:
    damage(run_dir)
    result = CliRunner().invoke(app, ["report", str(run_dir)])
    assert result.exit_code == 2
    assert "error:" in result.output and named in result.output
    assert "Traceback" not in result.output


def test_floor_only_a_side_brush_touched_is_drawn_and_counted_apart(run_dir: Path) -> None:
    """A stored run from before side brushes reads with none; given the cells a side brush
    touched, the picture paints the cleanable ones the main brush missed in the side brush's
    colour, the legend counts them, and missed floor no longer includes them."""
    data = load_run(run_dir)
    assert data.side is not None and not data.side.any()
    missed = data.cleanable & (data.visits == 0)
    assert missed.sum() > 10
    with np.load(run_dir / GRID_FILE) as npz:
        arrays = {k: npz[k] for k in npz.files}
    np.savez_compressed(run_dir / GRID_FILE, **arrays, side=missed)
    data = load_run(run_dir)
    assert np.array_equal(data.side, missed)
    assert not (data.cleanable & ~data.swept).any()
    rgb = floor_rgb(data.visits, data.cleanable, data.side)
    assert np.allclose(rgb[missed], matplotlib.colors.to_rgb(SIDE_COLOUR))
    fig, _ = map_figure(data)
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    res2 = data.resolution**2
    assert f"side brush only ({missed.sum() * res2:.2f} m²)" in labels
    assert "missed (0.00 m²)" in labels
