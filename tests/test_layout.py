"""The code's layout rules (docs/architecture.md, "The rooms"), read from the source files with
ast (nothing is imported; imports inside functions count too):

- arrows go one way: the face (``fleet.cli``, ``fleet.dashboard``, ``fleet.report``,
  ``fleet.bench``) -> the processes (``sim_server``, ``agents``, ``fleet.coordinator``) and the
  supervisor -> the spine (the modules at the root of ``fleet/``) and ``planners``;
- the spine imports no process, no supervisor and no face, and stays at most
  ``SPINE_MODULES`` modules;
- no process imports another: the simulator never imports robot software, the agent never
  the simulator or the coordinator;
- ``planners`` is pure: it imports nothing of the project outside itself, and never Zenoh;
- no command module of ``fleet/cli/`` imports another (they share ``fleet/cli/common.py``,
  ``fleet/cli/help_text.py`` and ``fleet/cli/options.py``);
- no import circle anywhere;
- no function in ``fleet/coordinator/``, ``agents/`` or ``planners/`` is longer than
  ``MAX_FUNCTION_LINES`` lines, and no class there longer than ``MAX_CLASS_LINES``;
- no function in ``fleet/cli/`` (nested ones included) is longer than ``MAX_FUNCTION_LINES``:
  a command parses its options and calls the room that does the work.

Each rule is checked by a function that takes the import graph, and each is shown to catch a
breach on a graph with one bad arrow added."""

from __future__ import annotations

import ast
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("fleet", "agents", "sim_server", "planners")
CLI = "fleet.cli"
CLI_SHARED = {
    "fleet.cli",
    "fleet.cli.common",
    "fleet.cli.help_text",
    "fleet.cli.options",
    "fleet.cli.__main__",
}
FACE = ("fleet.cli", "fleet.dashboard", "fleet.report", "fleet.bench")
PROCESSES = ("sim_server", "agents", "fleet.coordinator")
SUPERVISOR = "fleet.supervisor"
SPINE_MODULES = 14
MAX_FUNCTION_LINES = 80
MAX_CLASS_LINES = 350
SIZED = ("fleet/coordinator", "agents", "planners")

Graph = dict[str, set[str]]


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {
        _module_name(p): p for package in PACKAGES for p in sorted((ROOT / package).rglob("*.py"))
    }


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


def _graph() -> Graph:
    """Every import of each module of the project (the project's own and the others)."""
    modules = _modules()
    return {name: _imported(path, name, set(modules)) for name, path in modules.items()}


def _in(module: str, rooms: tuple[str, ...] | str) -> bool:
    rooms = (rooms,) if isinstance(rooms, str) else rooms
    return any(module == r or module.startswith(r + ".") for r in rooms)


def _spine() -> set[str]:
    """The modules at the root of fleet/ (fleet.protocol, fleet.bus, ...), and fleet itself."""
    return {"fleet"} | {
        name
        for name, path in _modules().items()
        if path.parent == ROOT / "fleet" and path.name != "__init__.py"
    }


def _own_edges(graph: Graph) -> Graph:
    return {m: {i for i in imports if i in graph and i != m} for m, imports in graph.items()}


def _cycle(edges: Graph) -> list[str] | None:
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


def _spine_breaches(graph: Graph) -> list[str]:
    bad_rooms = (*PROCESSES, SUPERVISOR, *FACE)
    spine = _spine()
    return [
        f"{m} (spine) imports {i}"
        for m, imports in graph.items()
        if m in spine
        for i in sorted(imports)
        if _in(i, bad_rooms)
    ]


def _process_breaches(graph: Graph) -> list[str]:
    """A process importing another process, the supervisor or the face."""
    out = []
    for m, imports in graph.items():
        own = next((p for p in PROCESSES if _in(m, p)), None)
        if own is None and not _in(m, SUPERVISOR):
            continue
        for i in sorted(imports):
            other = next((p for p in PROCESSES if _in(i, p)), None)
            if (
                (other is not None and other != own)
                or _in(i, FACE)
                or (own is not None and _in(i, SUPERVISOR))
            ):
                out.append(f"{m} imports {i}")
    return out


def _planner_breaches(graph: Graph) -> list[str]:
    return [
        f"{m} (pure) imports {i}"
        for m, imports in graph.items()
        if _in(m, "planners")
        for i in sorted(imports)
        if _in(i, ("fleet", "agents", "sim_server", "zenoh"))
    ]


def _cli_breaches(graph: Graph) -> list[str]:
    commands = [m for m in graph if _in(m, CLI) and m not in CLI_SHARED]
    return [
        f"{m} imports command module {i}; share via fleet/cli/common.py or options.py"
        for m in commands
        for i in sorted(graph[m])
        if _in(i, CLI) and i not in CLI_SHARED and i != m
    ]


def _with_arrow(graph: Graph, src: str, dst: str) -> Graph:
    return {**graph, src: graph[src] | {dst}}


RULES: dict[str, Callable[[Graph], list[str]]] = {
    "spine": _spine_breaches,
    "processes": _process_breaches,
    "planners": _planner_breaches,
    "cli": _cli_breaches,
}


def test_the_graph_sees_imports_inside_functions() -> None:
    graph = _graph()
    assert "fleet.cli.up" in graph["fleet.cli"]  # `from fleet.cli import up` in _register_all
    assert "fleet.bench.slam_outputs" in graph["fleet.bench.slam"]  # inside run_slam_bench


def test_the_cycle_finder_finds_a_circle() -> None:
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_no_import_circle() -> None:
    edges = _own_edges(_graph())
    assert len(edges) > 100, sorted(edges)
    circle = _cycle(edges)
    assert circle is None, "import circle: " + " -> ".join(circle or [])


def test_arrows_go_one_way() -> None:
    graph = _graph()
    for rule, breaches in RULES.items():
        found = breaches(graph)
        assert not found, f"{rule}: " + "; ".join(found)


def test_each_rule_catches_a_bad_arrow() -> None:
    """The rules are not vacuous: one bad arrow added to today's graph breaks each."""
    graph = _graph()
    bad = {
        "spine": ("fleet.protocol", "fleet.report.summary"),
        "processes": ("sim_server.server", "agents.slam.slam"),
        "planners": ("planners.dwa", "fleet.params"),
        "cli": ("fleet.cli.up", "fleet.cli.report"),
    }
    for rule, (src, dst) in bad.items():
        assert RULES[rule](_with_arrow(graph, src, dst)), f"{rule} missed {src} -> {dst}"
    assert _process_breaches(_with_arrow(graph, "agents.agent", "fleet.coordinator.job"))
    assert _process_breaches(_with_arrow(graph, "sim_server.core", "fleet.dashboard.model"))
    assert _planner_breaches(_with_arrow(graph, "planners.grid", "zenoh"))


def test_the_spine_is_small() -> None:
    spine = sorted(_spine() - {"fleet"})
    assert len(spine) <= SPINE_MODULES, spine


def test_the_cli_has_command_modules() -> None:
    commands = {m for m in _graph() if _in(m, CLI) and m not in CLI_SHARED}
    assert {"fleet.cli.up", "fleet.cli.processes", "fleet.cli.slam"} <= commands


def _oversized(paths: list[Path], root: Path = ROOT) -> list[str]:
    out = []
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            limit = (
                MAX_FUNCTION_LINES
                if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
                else MAX_CLASS_LINES
                if isinstance(node, ast.ClassDef)
                else None
            )
            if limit is not None and (n := node.end_lineno - node.lineno + 1) > limit:
                out.append(f"{path.relative_to(root)}:{node.lineno} {node.name} {n} lines")
    return out


def test_functions_and_classes_stay_small() -> None:
    paths = [p for room in SIZED for p in sorted((ROOT / room).rglob("*.py"))]
    assert len(paths) > 50
    found = _oversized(paths)
    assert not found, "; ".join(found)


def test_the_size_check_sees_a_long_function(tmp_path: Path) -> None:
    long = tmp_path / "long.py"
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES))
    long.write_text(f"def f():\n{body}\n")
    assert _oversized([long], tmp_path) == [f"long.py:1 f {MAX_FUNCTION_LINES + 1} lines"]
    long.write_text(f"def f():\n{body[: body.rindex(chr(10))]}\n")
    assert _oversized([long], tmp_path) == []


def test_the_size_check_sees_nested_and_async_functions(tmp_path: Path) -> None:
    long = tmp_path / "long.py"
    body = "\n".join(f"        x{i} = {i}" for i in range(MAX_FUNCTION_LINES))
    long.write_text(f"def outer():\n    async def inner():\n{body}\n")
    assert _oversized([long], tmp_path) == [
        f"long.py:1 outer {MAX_FUNCTION_LINES + 2} lines",
        f"long.py:2 inner {MAX_FUNCTION_LINES + 1} lines",
    ]


def test_the_cli_commands_stay_small() -> None:
    paths = sorted((ROOT / "fleet" / "cli").glob("*.py"))
    assert {"up.py", "processes.py"} <= {p.name for p in paths}
    found = _oversized(paths)
    assert not found, "; ".join(found)


def test_params_reach_no_robot_or_simulator_software() -> None:
    """fleet/params.py and every module it imports, transitively, import nothing from agents/
    or sim_server/ (the simulator loads the parameters)."""
    graph = _graph()
    edges = _own_edges(graph)
    seen, todo = set(), ["fleet.params"]
    while todo:
        m = todo.pop()
        if m in seen:
            continue
        seen.add(m)
        todo.extend(edges[m])
        bad = sorted(i for i in graph[m] if i.split(".")[0] in ("agents", "sim_server"))
        assert not bad, f"{m} (imported by fleet.params) imports {bad}"
    assert "fleet.slam_params" in seen


def duplicate_test_names(root: Path) -> list[str]:
    """Test file names used in more than one folder under ``root``: pytest imports test files
    by their bare name (no packages), so the second one fails to be collected at all."""
    seen: dict[str, list[Path]] = {}
    for path in sorted(root.rglob("test_*.py")):
        seen.setdefault(path.name, []).append(path)
    return [name for name, paths in seen.items() if len(paths) > 1]


def test_no_two_test_files_share_a_name(tmp_path: Path) -> None:
    assert duplicate_test_names(ROOT / "tests") == []
    for folder in ("fleet", "integration"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "test_chaos_bench.py").write_text("")
    assert duplicate_test_names(tmp_path) == ["test_chaos_bench.py"]
