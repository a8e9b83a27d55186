"""A non-editable install (`pip install .`, as the Dockerfile does) carries configs/ as the
package fleet.configs, with no __init__.py: the built-in configs and worlds must be found
there, not only in a source checkout. The wheel's layout is laid out by hand in a temporary
dir (copying the packages as pyproject.toml maps them) and imported from there in a fresh
interpreter, outside the checkout."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import tomllib

ROOT = Path(__file__).resolve().parents[2]


def test_built_in_configs_and_worlds_are_found_in_an_installed_layout(tmp_path: Path) -> None:
    site = tmp_path / "site"
    for package in ("fleet", "agents", "sim_server", "planners"):
        shutil.copytree(ROOT / package, site / package, ignore=shutil.ignore_patterns("*.pyc"))
    shutil.copytree(ROOT / "configs", site / "fleet" / "configs")
    probe = (
        "import json; from fleet.config import configs_dir, default_world_path, resolve_world; "
        "from fleet.params import load_fleet_config; "
        "print(json.dumps([str(configs_dir()), str(default_world_path()), "
        "str(resolve_world('small')), load_fleet_config().robot.radius]))"
    )
    out = subprocess.run(
        [sys.executable, "-c", probe],
        cwd=tmp_path,
        env={"PYTHONPATH": str(site), "PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert out.returncode == 0, out.stderr
    configs, home, small, radius = json.loads(out.stdout)
    assert Path(configs) == site / "fleet" / "configs"
    assert Path(home) == site / "fleet" / "configs" / "worlds" / "home.yaml"
    assert Path(small).is_file() and radius > 0


def test_every_package_is_in_the_distribution() -> None:
    """pyproject.toml lists the packages by hand: a new folder of modules must be in it, or a
    non-editable install lacks it."""
    listed = set(
        tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]
    )
    found = {
        ".".join(init.parent.relative_to(ROOT).parts)
        for package in ("fleet", "agents", "sim_server", "planners")
        for init in (ROOT / package).rglob("__init__.py")
    }
    assert found - listed == set(), f"missing from pyproject.toml: {sorted(found - listed)}"
