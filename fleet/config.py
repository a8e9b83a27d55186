"""Typed, validated configuration.

`configs/fleet.yaml` holds one mapping per section (robot, lidar, odometry, sim, dwa, ...). Each
section is loaded into a frozen dataclass; every error names the file and the dotted field.
The consumers own their parameter dataclasses (``planners.dwa.DWAParams`` etc.); this module only
knows which section maps to which class.
"""

from __future__ import annotations

import dataclasses
import difflib
import types
import typing
from collections.abc import Iterable
from importlib import resources
from pathlib import Path
from typing import Any, TypeVar

import yaml

T = TypeVar("T")


class ConfigError(ValueError):
    """A configuration file is missing, unreadable or invalid. The message names file and field."""


def configs_dir() -> Path:
    """The directory with the built-in configs (fleet.yaml, worlds/, zenoh/).

    In a source checkout that is ``configs/`` beside the packages; a wheel install carries the
    same files as the package ``fleet.configs``.
    """
    checkout = Path(__file__).resolve().parents[1] / "configs"
    if (checkout / "fleet.yaml").exists():
        return checkout
    # fleet.configs has no __init__.py: files() gives a MultiplexedPath, whose str() is no
    # path; a file joined to it is a plain one
    return Path(str(resources.files("fleet.configs").joinpath("fleet.yaml"))).parent


def default_world_path() -> Path:
    return configs_dir() / "worlds" / "home.yaml"


def resolve_world(name_or_path: str | Path) -> Path:
    """A world given as a path, or as the name of a built-in world (``home``, ``small``)."""
    p = Path(name_or_path)
    if p.exists():
        return p
    builtin = configs_dir() / "worlds" / f"{name_or_path}.yaml"
    if builtin.exists():
        return builtin
    raise ConfigError(f"{name_or_path}: no such world file, and no built-in world of that name")


def read_yaml(path: Path) -> Any:
    """Parse a YAML file; errors name the file (and line, where YAML gives one)."""
    try:
        text = Path(path).read_text()
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except OSError as e:
        raise ConfigError(f"{path}: cannot read: {e.strerror}") from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as e:
        where = ""
        mark = getattr(e, "problem_mark", None)
        if mark is not None:
            where = f" (line {mark.line + 1}, column {mark.column + 1})"
        problem = getattr(e, "problem", None) or str(e)
        raise ConfigError(f"{path}: invalid YAML{where}: {problem}") from None


def unknown_field(where: str, name: str, known: Iterable[str]) -> ConfigError:
    """The error for an unknown field ``name`` at ``where`` (file and dotted field), with the
    nearest known name as a hint for a typo and the known names."""
    known = sorted(known)
    close = difflib.get_close_matches(name, known, n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    return ConfigError(f"{where}: unknown field{hint} (known: {', '.join(known)})")


def _at(source: str, field: str) -> str:
    """``file: dotted.field`` (``file`` alone at the top level), the prefix of every error."""
    return f"{source}: {field}" if field else source


def _dotted(field: str, name: str) -> str:
    return f"{field}.{name}" if field else name


def _type_name(tp: Any) -> str:
    return getattr(tp, "__name__", str(tp))


def _coerce(value: Any, tp: Any, source: str, field: str) -> Any:
    """Check ``value`` against the annotation ``tp`` and convert (int → float, list → tuple);
    errors name ``source`` (the file) and ``field`` (dotted)."""
    where = _at(source, field)
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if tp is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        for a in args:
            if a is type(None):
                continue
            try:
                return _coerce(value, a, source, field)
            except ConfigError as e:
                errors.append(str(e))
        raise ConfigError(errors[0] if errors else f"{where}: invalid value {value!r}")
    if origin is typing.Literal:
        if value not in args:
            raise ConfigError(f"{where}: must be one of {list(args)}, got {value!r}")
        return value
    if origin in (tuple, list):
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where}: expected a list, got {value!r}")
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise ConfigError(f"{where}: expected {len(args)} items, got {len(value)}")
            items = [
                _coerce(v, a, source, f"{field}[{i}]")
                for i, (v, a) in enumerate(zip(value, args, strict=False))
            ]
        else:
            a = args[0] if args else Any
            items = [_coerce(v, a, source, f"{field}[{i}]") for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(f"{where}: expected a mapping, got {value!r}")
        ka, va = args or (Any, Any)
        return {
            _coerce(k, ka, source, field): _coerce(v, va, source, _dotted(field, str(k)))
            for k, v in value.items()
        }
    if dataclasses.is_dataclass(tp):
        return from_mapping(tp, value, source, field)
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: expected a number, got {value!r}")
        if value != value:
            raise ConfigError(f"{where}: NaN is not allowed")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    if isinstance(tp, type) and not isinstance(value, tp):
        raise ConfigError(f"{where}: expected {_type_name(tp)}, got {value!r}")
    return value


def from_mapping(cls: type[T], data: Any, source: str, field: str = "") -> T:
    """Build the dataclass ``cls`` from a mapping; unknown or mistyped fields raise ConfigError.

    Missing fields take the dataclass defaults. Errors begin with ``source`` (the file) and the
    dotted field, e.g. ``configs/fleet.yaml: dwa.sim_time``; ``field`` is where ``data`` sits
    in the file (empty at the top level). An unknown field's error suggests the nearest known
    name. A dataclass may define ``validate(self) -> None`` raising ValueError for cross-field
    checks; its message is prefixed with the file and ``field`` too.
    """
    where = _at(source, field)
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: expected a mapping, got {data!r}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(data) - set(fields), key=str)
    if unknown:
        raise unknown_field(_at(source, _dotted(field, str(unknown[0]))), str(unknown[0]), fields)
    kwargs = {}
    for name, f in fields.items():
        sub = _dotted(field, name)
        if name in data:
            kwargs[name] = _coerce(data[name], hints[name], source, sub)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ConfigError(f"{_at(source, sub)}: required field is missing")
    obj = cls(**kwargs)
    check = getattr(obj, "validate", None)
    if callable(check):
        try:
            check()
        except ValueError as e:
            raise ConfigError(f"{where}: {e}") from None
    return obj


def load_dataclass(cls: type[T], path: Path, section: str | None = None) -> T:
    """Load ``cls`` from a YAML file, or from one top-level section of it."""
    data = read_yaml(path)
    if section is None:
        return from_mapping(cls, data, str(path))
    if data is not None and not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping at the top level")
    return from_mapping(cls, (data or {}).get(section), str(path), section)
