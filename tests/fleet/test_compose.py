"""compose.yaml and the Dockerfile, without a container engine: the Compose file is valid by the
Compose Specification's JSON schema (tests/data/compose_spec, see SOURCE.md there), every
service's command is a `fleet` command line that the CLI itself accepts, with the environment
the service gets, and the processes meet only at the router's TCP endpoint."""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import typer
import yaml

from fleet.bus import validate_endpoint
from fleet.cli import app

ROOT = Path(__file__).resolve().parents[2]
SCHEMA = Path(__file__).resolve().parents[1] / "data" / "compose_spec" / "compose_spec.json"
# ${VAR}, ${VAR:-default}, ${VAR-default}, and $$ for a literal $
INTERPOLATION = re.compile(
    r"\$\$|\$\{(?P<name>[A-Za-z_][A-Za-z0-9_]*)(?:(?P<op>:?-)(?P<default>[^}]*))?\}"
)


def _interpolate(value: Any, env: dict[str, str]) -> Any:
    """Compose's variable interpolation, over every string of ``value``."""
    if isinstance(value, dict):
        return {k: _interpolate(v, env) for k, v in value.items()}
    if isinstance(value, list):
        return [_interpolate(v, env) for v in value]
    if not isinstance(value, str):
        return value

    def one(m: re.Match) -> str:
        if m.group(0) == "$$":
            return "$"
        name, op, default = m.group("name"), m.group("op"), m.group("default")
        if op == ":-" and not env.get(name):
            return default
        if op == "-" and name not in env:
            return default
        if name not in env:
            raise AssertionError(f"compose.yaml uses ${{{name}}} without a default")
        return env[name]

    return INTERPOLATION.sub(one, value)


def _compose(env: dict[str, str] | None = None) -> dict[str, Any]:
    return _interpolate(yaml.safe_load((ROOT / "compose.yaml").read_text()), env or {})


def _parse(argv: list[str], env: dict[str, str], monkeypatch: pytest.MonkeyPatch) -> typer.Context:
    """Parse ``fleet <argv>`` as the CLI would, with ``env`` as the process environment, down to
    the command that would run. An unknown command raises LookupError; an unknown option or a
    bad value raises the CLI's usage error ("No such option: ...")."""
    for name in [k for k in os.environ if k.startswith("FLEET_")]:
        monkeypatch.delenv(name)
    for name, value in env.items():
        monkeypatch.setenv(name, str(value))
    command = typer.main.get_command(app)
    parent = typer.Context(command, info_name="fleet")
    name, args = "fleet", list(argv)
    while hasattr(command, "get_command"):  # a group of commands
        if not args:
            raise LookupError(f"fleet {name} needs a command")
        name, *args = args
        sub = command.get_command(parent, name)
        if sub is None:
            raise LookupError(f"fleet has no command {name!r}")
        if hasattr(sub, "get_command"):
            parent = typer.Context(sub, info_name=name, parent=parent)
        command = sub
    return command.make_context(name, args, parent=parent)


def _leaf_name(ctx: typer.Context) -> str:
    names = []
    while ctx.parent is not None:
        names.append(ctx.info_name)
        ctx = ctx.parent
    return " ".join(reversed(names))


def test_compose_yaml_is_valid_by_the_compose_specification() -> None:
    schema = yaml.safe_load(SCHEMA.read_text())
    # the schema names its draft by an older URL of 2019-09's metaschema
    assert "2019-09" in schema["$schema"]
    validator = jsonschema.Draft201909Validator(schema)
    raw = yaml.safe_load((ROOT / "compose.yaml").read_text())
    errors = [f"{'/'.join(map(str, e.path))}: {e.message}" for e in validator.iter_errors(raw)]
    assert errors == []
    # the schema is strict enough to catch a misspelt key
    raw["services"]["sim"]["comand"] = raw["services"]["sim"].pop("command")
    assert not validator.is_valid(raw)


SERVICE_COMMANDS = {
    "router": "router",
    "sim": "sim",
    "coordinator": "coordinator",
    "dashboard": "dashboard",
}


@pytest.mark.parametrize(
    "env", [{}, {"FLEET_WORLD": "small", "FLEET_ROBOTS": "2", "FLEET_SPEED": "4"}]
)
def test_every_service_runs_a_fleet_command_line_the_cli_accepts(
    env: dict[str, str], monkeypatch: pytest.MonkeyPatch
) -> None:
    services = _compose(env)["services"]
    commands = set(typer.main.get_command(app).commands)
    agents = {}
    for name, service in services.items():
        argv = service["command"]
        assert isinstance(argv, list) and argv[0] == "fleet", f"{name}: {argv}"
        if argv[1] == "dashboard" and argv[1] not in commands:
            continue  # test_the_dashboard_service_runs_fleet_dashboard
        ctx = _parse(argv[1:], service.get("environment", {}), monkeypatch)
        verb = _leaf_name(ctx)
        assert verb == SERVICE_COMMANDS.get(name, "agent"), f"{name} runs fleet {verb}"
        params = ctx.params
        if verb == "router":
            assert params["listen"] == ["tcp/0.0.0.0:7447"]
            continue
        assert params["connect"] == ["tcp/router:7447"], name
        for endpoint in params["connect"]:
            validate_endpoint(endpoint)
        if "world" in params:
            assert params["world"] == env.get("FLEET_WORLD", "home"), name
        if verb == "agent":
            agents[params["robot_id"]] = params
    assert sorted(agents) == ["robot-0", "robot-1", "robot-2"]
    assert sorted(a["start_index"] for a in agents.values()) == [0, 1, 2]
    assert len({a["state_dir"] for a in agents.values()}) == 3


def test_the_dashboard_service_runs_fleet_dashboard(monkeypatch: pytest.MonkeyPatch) -> None:
    service = _compose()["services"]["dashboard"]
    if "dashboard" not in typer.main.get_command(app).commands:
        pytest.skip("`fleet dashboard` (the live view of issue 17) is not in the CLI yet")
    ctx = _parse(service["command"][1:], service["environment"], monkeypatch)
    assert _leaf_name(ctx) == "dashboard"
    connect = ctx.params["connect"]
    assert (connect if isinstance(connect, list) else [connect]) == ["tcp/router:7447"]
    assert service["tty"] and service["stdin_open"]


def test_a_misspelt_option_in_a_service_command_would_fail(monkeypatch: pytest.MonkeyPatch) -> None:
    argv = _compose()["services"]["robot-0"]["command"][1:]
    with pytest.raises(Exception, match="No such option: --stat-dir"):
        _parse([*argv, "--stat-dir", "/data"], {}, monkeypatch)
    with pytest.raises(Exception, match=r"(greater than or equal to 0|x>=0)"):
        _parse([*argv, "--start-index", "-1"], {}, monkeypatch)
    with pytest.raises(LookupError, match="no command 'agentt'"):
        _parse(["agentt", "--id", "robot-0"], {}, monkeypatch)


def test_the_router_is_published_and_each_agent_keeps_its_state_in_its_own_volume() -> None:
    compose = _compose({"FLEET_ROUTER_PORT": "17447"})
    assert compose["services"]["router"]["ports"] == ["17447:7447"]
    for rid in ("robot-0", "robot-1", "robot-2"):
        service = compose["services"][rid]
        assert service["volumes"] == [f"{rid}:/data"]
        assert rid in compose["volumes"]
        assert "router" in service["depends_on"]


def test_the_dockerfile_copies_every_package_the_distribution_installs() -> None:
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    tops = {p.split(".")[0] for p in pyproject["tool"]["setuptools"]["packages"]}
    dirs = set(pyproject["tool"]["setuptools"]["package-dir"].values())
    copied = set(re.findall(r"^COPY (\S+) \1$", (ROOT / "Dockerfile").read_text(), re.M))
    assert (tops | dirs) - {"fleet.configs"} <= copied
