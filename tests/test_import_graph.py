"""The package's modules import one another without cycles (function-level imports included)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
from fresh_imports import loaded_modules
from test_package_xml import imported_roots

PACKAGE = Path(__file__).resolve().parents[1] / "ros2_ws" / "src" / "pose_lifter" / "pose_lifter"


def _modules() -> dict[str, Path]:
    out = {}
    for f in PACKAGE.rglob("*.py"):
        parts = ("pose_lifter", *f.relative_to(PACKAGE).with_suffix("").parts)
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = f
    return out


def import_graph() -> dict[str, set[str]]:
    """module -> the package modules it imports anywhere in its file."""
    mods = _modules()
    graph: dict[str, set[str]] = {}
    for name, f in mods.items():
        pkg = name if f.name == "__init__.py" else name.rsplit(".", 1)[0]
        deps: set[str] = set()
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = pkg.split(".")[: len(pkg.split(".")) - (node.level - 1)]
                    mod = ".".join([*base, node.module] if node.module else base)
                else:
                    mod = node.module or ""
                deps.update(c for c in [mod, *(f"{mod}.{a.name}" for a in node.names)] if c in mods)
            elif isinstance(node, ast.Import):
                deps.update(a.name for a in node.names if a.name in mods)
        deps.discard(name)
        graph[name] = deps
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_cycle_finder_finds_a_cycle() -> None:
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_module_of_the_package_imports_itself_through_others() -> None:
    graph = import_graph()
    assert "pose_lifter.cli" in graph and "pose_lifter.core.lift.lifter" in graph["pose_lifter.offline.lift"]
    assert cycles(graph) == []


def test_the_core_never_imports_the_ros_shell() -> None:
    graph = import_graph()
    for name, deps in graph.items():
        if name.startswith("pose_lifter.core"):
            assert all(d.startswith("pose_lifter.core") for d in deps), (name, deps)


def test_the_error_tree_and_the_bag_reader_load_without_the_solver() -> None:
    loaded = loaded_modules("pose_lifter.offline.bags", "pose_lifter.core.errors")
    assert "pose_lifter.offline.bags" in loaded
    assert not loaded & {"numba", "scipy", "pose_lifter.core.lift.lifter"}


def test_every_public_core_name_resolves_lazily() -> None:
    import pose_lifter.core as core
    from pose_lifter.core.lift.lifter import Lifter

    assert core.Lifter is Lifter
    for name in core.__all__:
        assert getattr(core, name) is not None
    assert set(core.__all__) <= set(dir(core))
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        _ = core.nope  # type: ignore[attr-defined]


def test_rclpy_is_imported_only_under_ros() -> None:
    mods = _modules()
    ros = {name for name, f in mods.items() if "rclpy" in imported_roots(f)}
    assert "pose_lifter.ros.node" in ros  # the check reads imports at all
    assert all(name.startswith("pose_lifter.ros.") for name in ros), sorted(ros)
    # and the rest of the package never imports the ROS shell
    for name, deps in import_graph().items():
        if not name.startswith(("pose_lifter.ros", "pose_lifter.cli")):
            assert not any(d.startswith("pose_lifter.ros") for d in deps), (name, deps)


#: The rooms each room of the package may import (the package itself, which holds the version,
#: any room): the command line over everything; the node over the offline reader, the messages and
#: the core, never the mocap side (data, training, experiments), which stands beside the offline
#: lift and reaches its writer only through the command line.
ROOM_IMPORTS: dict[str, set[str]] = {
    "cli": {"ros", "mocap", "offline", "messages", "actions", "core"},
    "ros": {"offline", "messages", "actions", "core"},
    "mocap": {"messages", "core"},
    "offline": {"messages", "core"},
    "messages": {"core"},
    "actions": {"core"},
    "core": set(),
}
#: The core's parts in the order the walk of one frame goes down them: a part imports only parts
#: below it (the modules at ``core/``'s top, the errors, options, results and input checks, and the
#: reference and baseline solvers, are outside this order).
CORE_PARTS = ("track", "lift", "solve", "model", "numeric")


def _room(name: str) -> str | None:
    parts = name.split(".")
    return parts[1] if len(parts) > 1 else None


def _core_part(name: str) -> str | None:
    parts = name.split(".")
    return parts[2] if len(parts) > 3 and parts[1] == "core" and parts[2] in CORE_PARTS else None


def test_every_arrow_between_rooms_and_between_core_parts_runs_down() -> None:
    graph = import_graph()
    rooms_up, parts_up, parts_down = [], [], 0
    for name, deps in graph.items():
        for d in deps:
            a, b = _room(name), _room(d)
            if a is not None and b is not None and a != b and b not in ROOM_IMPORTS[a]:
                rooms_up.append((name, d))
            pa, pb = _core_part(name), _core_part(d)
            if pa is not None and pb is not None and pa != pb:
                if CORE_PARTS.index(pb) < CORE_PARTS.index(pa):
                    parts_up.append((name, d))
                else:
                    parts_down += 1
    assert not rooms_up, rooms_up
    assert not parts_up, parts_up
    # the rule reads real arrows: the tracks call the lifter, the lifter the compiled runs
    assert "pose_lifter.core.lift.lifter" in graph["pose_lifter.core.track.policy"]
    assert parts_down > 20
    assert set(ROOM_IMPORTS) == {_room(name) for name in graph} - {None}


#: The package's size rules: a module a reader can hold, a call a reader can check.
MAX_MODULE_LINES = 600
MAX_PARAMETERS = 15


def _parameters(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    a = fn.args
    n = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + (a.vararg is not None) + (a.kwarg is not None)
    return n - bool(a.args and a.args[0].arg in ("self", "cls"))


def test_no_module_is_too_long_and_no_function_takes_too_many_parameters() -> None:
    lines = {name: len(f.read_text().splitlines()) for name, f in _modules().items()}
    long = {name: n for name, n in lines.items() if n > MAX_MODULE_LINES}
    assert not long, long
    wide = [(name, fn.name, _parameters(fn)) for name, f in _modules().items()
            for fn in ast.walk(ast.parse(f.read_text()))
            if isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef) and _parameters(fn) > MAX_PARAMETERS]
    assert not wide, wide
    # the rule reads what it claims to: a function of 16 parameters is caught
    wide_src = "def f(" + ", ".join(f"a{i}" for i in range(16)) + "): pass"
    assert _parameters(ast.parse(wide_src).body[0]) == 16  # type: ignore[arg-type]
