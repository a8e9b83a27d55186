"""``fleet slam replay``: run the agents' SLAM offline on a CARMEN log and write its results."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer


def register(
    app: typer.Typer, plan_app: typer.Typer, bench_app: typer.Typer, slam_app: typer.Typer
) -> None:
    slam_app.command("replay")(replay)


def replay(
    log: Annotated[
        Path,
        typer.Argument(
            help="CARMEN log (FLASER / ROBOTLASER1 / ODOM lines; .gz is read transparently)."
        ),
    ],
    out: Annotated[
        Path,
        typer.Option(help="Directory for map.png, map.yaml, trajectory.csv and timing.json."),
    ] = Path("slam-replay"),
    config: Annotated[
        Path | None,
        typer.Option(help="fleet.yaml whose `slam:` section to use (default: the built-in one)."),
    ] = None,
    range_min: Annotated[
        float, typer.Option(help="Shorter returns are treated as no return (metres).")
    ] = 0.05,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print one JSON object instead of a table.")
    ] = False,
) -> None:
    """Replay a recorded CARMEN log through the same SLAM the agents run.

    Writes, into --out: map.png (ROS map_server colours: black occupied, white free, grey
    unknown; with map.yaml beside it), trajectory.csv (header t,x,y,theta: the pose after each
    scan, as corrected by the final loop-closure optimization) and timing.json (milliseconds
    per scan, replay speed as a multiple of real time, loop closures).

    Example: fleet slam replay intel.gfs.log.gz --out /tmp/intel
    """
    from agents.slam.carmen import CarmenParseError, read_log
    from agents.slam.replay import replay_log
    from fleet.config import ConfigError
    from fleet.params import load_fleet_config

    try:
        params = load_fleet_config(config).slam
        parsed = read_log(log)
        result = replay_log(parsed, params, range_min=range_min)
    except (CarmenParseError, ConfigError) as e:
        typer.echo(f"error: {e}", err=True)
        raise typer.Exit(2) from None
    except ValueError as e:
        typer.echo(f"error: {log}: {e}", err=True)
        raise typer.Exit(2) from None
    summary = _write_outputs(result, parsed, out, params, log)
    if as_json:
        typer.echo(json.dumps(summary))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"SLAM replay of {log.name}")
    table.add_column("metric")
    table.add_column("value", justify="right")
    for key, value in summary.items():
        table.add_row(key, f"{value:.3f}" if isinstance(value, float) else str(value))
    Console().print(table)


def _write_outputs(result, parsed, out: Path, params, log: Path) -> dict:
    import numpy as np
    from PIL import Image

    out.mkdir(parents=True, exist_ok=True)
    np.savetxt(
        out / "trajectory.csv",
        result.trajectory,
        delimiter=",",
        header="t,x,y,theta",
        comments="",
        fmt=["%.6f", "%.4f", "%.4f", "%.5f"],
    )
    slam_map = result.slam.occupancy()
    p = slam_map.probabilities()
    image = np.full(p.shape, 205, dtype=np.uint8)
    image[p >= params.occupied_threshold] = 0
    image[p <= params.free_threshold] = 254
    Image.fromarray(image[::-1]).save(out / "map.png")
    (out / "map.yaml").write_text(
        "image: map.png\n"
        f"resolution: {slam_map.resolution}\n"
        f"origin: [{slam_map.origin[0]}, {slam_map.origin[1]}, 0.0]\n"
        "negate: 0\n"
        f"occupied_thresh: {params.occupied_threshold}\n"
        f"free_thresh: {params.free_threshold}\n"
    )
    ms = result.scan_seconds * 1000.0
    stats = result.slam.stats()
    summary = {
        "log": str(log),
        "scans": int(ms.size),
        "log_seconds": result.log_seconds,
        "processing_seconds": float(result.scan_seconds.sum()),
        "ms_per_scan_median": float(np.median(ms)),
        "ms_per_scan_p95": float(np.percentile(ms, 95)),
        "ms_per_scan_max": float(ms.max()),
        "replay_speedup": result.speedup,
        "nodes": stats.nodes,
        "submaps": stats.submaps,
        "loop_closures": stats.loop_closures,
        "optimizations": stats.optimizations,
        "skipped_messages": dict(parsed.skipped),
        "truncated_line": parsed.truncated_line,
        "out": str(out),
    }
    (out / "timing.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary
