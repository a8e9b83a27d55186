"""The code's layout rules, read from the source files with ast (nothing is imported):
no import circle among the modules of fleet/ (fleet/cli/ included, imports inside functions
too), no command module of fleet/cli/ importing another (they share fleet/cli/common.py), and
fleet/params.py reaching no robot or simulator software."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "fleet"
CLI = "fleet.cli"
CLI_SHARED = {"fleet.cli", "fleet.cli.common", "fleet.cli.__main__"}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted((ROOT / PACKAGE).rglob("*.py"))}


def _imported(path: Path, name: str, modules: set[str]) -> set[str]:
    """Every module name ``path`` imports, at any depth of its code: ``import a.b`` gives
    a.b, ``from a import b`` gives a.b when that is one of ``modules``, else a."""
    is_package = path.name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".")
                base = base[: len(base) - node.level + (1 if is_package else 0)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            for alias in node.names:
                sub = f"{module}.{alias.name}"
                found.add(sub if sub in modules else module)
    return found


def _graph() -> tuple[dict[str, set[str]], dict[str, set[str]]]:
    """The edges between fleet's own modules, and every import of each module."""
    modules = _modules()
    edges: dict[str, set[str]] = {}
    imports: dict[str, set[str]] = {}
    for name, path in modules.items():
        imports[name] = _imported(path, name, set(modules))
        edges[name] = {m for m in imports[name] if m in modules and m != name}
    return edges, imports


def _cycle(edges: dict[str, set[str]]) -> list[str] | None:
    """One import circle, as the list of modules around it, or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(edges.get(node, ())):
            if state.get(nxt) == 1:
                return [*path[path.index(nxt) :], nxt]
            if nxt not in state and (found := visit(nxt)) is not None:
                return found
        path.pop()
        state[node] = 2
        return None

    for start in sorted(edges):
        if start not in state and (found := visit(start)) is not None:
            return found
    return None


def test_the_cycle_finder_finds_a_circle() -> None:
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_the_graph_sees_imports_inside_functions() -> None:
    edges, _ = _graph()
    assert "fleet.cli.up" in edges["fleet.cli"]  # `from fleet.cli import up` in _register_all
    assert "fleet.slam_outputs" in edges["fleet.slam_bench"]  # inside run_slam_bench


def test_no_import_circle_in_fleet() -> None:
    edges, _ = _graph()
    assert len(edges) > 30, sorted(edges)
    circle = _cycle(edges)
    assert circle is None, "import circle: " + " -> ".join(circle or [])


def test_no_command_module_imports_another() -> None:
    edges, _ = _graph()
    commands = [m for m in edges if m.startswith(CLI + ".") and m not in CLI_SHARED]
    assert {"fleet.cli.up", "fleet.cli.processes", "fleet.cli.slam"} <= set(commands)
    for m in commands:
        others = {e for e in edges[m] if e.startswith(CLI) and e not in CLI_SHARED}
        assert not others, f"{m} imports command modules {sorted(others)}; share via common.py"


def test_params_reach_no_robot_or_simulator_software() -> None:
    """fleet/params.py and every fleet module it imports, transitively, import nothing from
    agents/ or sim_server/ (the simulator loads the parameters)."""
    edges, imports = _graph()
    seen, todo = set(), ["fleet.params"]
    while todo:
        m = todo.pop()
        if m in seen:
            continue
        seen.add(m)
        todo.extend(edges[m])
        bad = sorted(i for i in imports[m] if i.split(".")[0] in ("agents", "sim_server"))
        assert not bad, f"{m} (imported by fleet.params) imports {bad}"
    assert "fleet.slam_params" in seen
