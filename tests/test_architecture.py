"""Layering of the clothfold_ros package, read statically with ast (nothing is imported).

1. The package's module import graph has no cycle. Every import statement counts,
   including imports inside functions (the kind that hid lookup/sweep <-> lookup/table).
2. Outside the ROS adapters (clothfold_ros/nodes/, clothfold_ros/cli/) no module imports
   rclpy or a ROS interface package, directly or through other package modules.

How edges are resolved: `from .x import y` gives an edge to module `x.y` if that is a
module of the package, else to `x`; `import a.b` to the longest known prefix. Importing
a submodule also runs its parent package's __init__; that implicit step is not an edge
(it cannot make a cycle by itself), an explicit `from . import name` of a non-module is.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG_ROOT = Path(__file__).resolve().parents[1] / "clothfold_ros"
ROS_ZONES = ("clothfold_ros.nodes", "clothfold_ros.cli")
ROS_ROOTS = {"rclpy", "launch", "launch_ros", "rosidl_runtime_py", "rosidl_parser", "rosidl_pycommon", "rosbag2_py",
             "ament_index_python", "message_filters", "tf2_ros", "rmw", "rcl"}
ROS_SUFFIXES = ("_msgs", "_srvs", "_interfaces", "_actions")

#: Modules outside the ROS zones that may import ROS, with the reason (none today). Each
#: entry must still be true (the test fails on a stale entry), so this is the current truth.
KNOWN_ROS_VIOLATIONS: dict[str, str] = {}


def is_ros(top: str) -> bool:
    return top in ROS_ROOTS or top.endswith(ROS_SUFFIXES)


def module_names(root: Path) -> dict[str, Path]:
    """Dotted module name -> file for every .py file of the package under `root`."""
    out = {}
    for f in sorted(root.rglob("*.py")):
        if "__pycache__" in f.parts:
            continue
        parts = list(f.relative_to(root.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = f
    return out


def import_graph(root: Path) -> tuple[dict[str, set[str]], dict[str, set[str]]]:
    """(package edges: module -> modules it imports, external: module -> top-level names)."""
    mods = module_names(root)
    edges: dict[str, set[str]] = {m: set() for m in mods}
    external: dict[str, set[str]] = {m: set() for m in mods}
    for mod, path in mods.items():
        is_pkg = path.name == "__init__.py"
        package = mod if is_pkg else mod.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    _add(mod, alias.name, None, mods, edges, external)
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")
                    if node.level > 1:
                        base = base[: len(base) - (node.level - 1)]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                _add(mod, target, [a.name for a in node.names], mods, edges, external)
    return edges, external


def _add(mod, target, names, mods, edges, external) -> None:
    top = target.split(".")[0]
    if top != "clothfold_ros":
        external[mod].add(top)
        return
    if names:
        for n in names:
            sub = f"{target}.{n}"
            if sub in mods:
                edges[mod].add(sub)
            elif target in mods:
                edges[mod].add(target)
        return
    parts = target.split(".")
    for k in range(len(parts), 0, -1):
        if ".".join(parts[:k]) in mods:
            edges[mod].add(".".join(parts[:k]))
            return


def find_cycle(edges: dict[str, set[str]]) -> list[str] | None:
    """One import cycle as [a, b, ..., a], or None (iterative DFS, white/grey/black)."""
    state: dict[str, int] = {}
    for start in sorted(edges):
        if state.get(start):
            continue
        stack = [(start, iter(sorted(edges[start] - {start})))]
        path = [start]
        state[start] = 1
        while stack:
            node, it = stack[-1]
            nxt = next(it, None)
            if nxt is None:
                state[node] = 2
                stack.pop()
                path.pop()
            elif state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            elif not state.get(nxt):
                state[nxt] = 1
                path.append(nxt)
                stack.append((nxt, iter(sorted(edges.get(nxt, set()) - {nxt}))))
    return None


def in_ros_zone(mod: str) -> bool:
    return any(mod == z or mod.startswith(z + ".") for z in ROS_ZONES)


def reach(edges: dict[str, set[str]], start: str) -> dict[str, str]:
    """Modules reachable from `start` -> the module that imports them first (for chains)."""
    seen, todo = {start: ""}, [start]
    while todo:
        m = todo.pop()
        for n in sorted(edges[m]):
            if n not in seen:
                seen[n] = m
                todo.append(n)
    return seen


def chain(seen: dict[str, str], end: str) -> list[str]:
    out = [end]
    while seen[out[-1]]:
        out.append(seen[out[-1]])
    return out[::-1]


@pytest.fixture(scope="module")
def graph():
    return import_graph(PKG_ROOT)


def test_the_graph_is_real(graph):
    """Guards against passing vacuously: the analysis sees the package as it is."""
    edges, external = graph
    assert len(edges) >= 40, sorted(edges)
    assert sum(len(v) for v in edges.values()) >= 80
    # the sweep-directory layout has one owner, imported by the engine and the table
    assert "clothfold_ros.lookup.sweep_dir" in edges["clothfold_ros.lookup.sweep"]
    assert "clothfold_ros.lookup.sweep_dir" in edges["clothfold_ros.lookup.table"]
    assert "clothfold_ros.lookup.sweep" not in edges["clothfold_ros.lookup.table"]
    assert "clothfold_ros.lookup.table" not in edges["clothfold_ros.lookup.sweep_dir"]
    # function-level imports are seen: sim/__init__ loads runner lazily in __getattr__
    assert "clothfold_ros.sim.runner" in edges["clothfold_ros.sim"]
    # the ROS detector sees the adapters' imports
    ros_users = [m for m, ext in external.items() if any(is_ros(t) for t in ext)]
    assert sum(in_ros_zone(m) for m in ros_users) >= 5, ros_users


def test_no_import_cycle(graph):
    edges, _ = graph
    cycle = find_cycle(edges)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_pure_core_never_imports_ros(graph):
    edges, external = graph
    direct = {m for m, ext in external.items() if any(is_ros(t) for t in ext)}
    problems = []
    for mod in sorted(edges):
        if in_ros_zone(mod) or mod in KNOWN_ROS_VIOLATIONS:
            continue
        seen = reach(edges, mod)
        bad = sorted(m for m in seen if m in direct)
        if bad:
            names = sorted(t for t in external[bad[0]] if is_ros(t))
            problems.append(f"{' -> '.join(chain(seen, bad[0]))} imports {', '.join(names)}")
    assert not problems, "ROS imports outside nodes/ and cli/:\n" + "\n".join(problems)


def test_known_violations_are_current(graph):
    edges, external = graph
    for mod, why in KNOWN_ROS_VIOLATIONS.items():
        assert mod in edges, f"{mod} no longer exists: remove it from KNOWN_ROS_VIOLATIONS ({why})"
        assert any(is_ros(t) for t in external[mod]), \
            f"{mod} no longer imports ROS: remove it from KNOWN_ROS_VIOLATIONS"


def test_the_checks_catch_a_hidden_cycle_and_a_ros_import(tmp_path):
    pkg = tmp_path / "clothfold_ros"
    (pkg / "lookup").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "lookup" / "__init__.py").write_text("")
    (pkg / "lookup" / "a.py").write_text("def f():\n    from .b import g\n    return g\n")
    (pkg / "lookup" / "b.py").write_text("import json\n\ndef g():\n    from . import a\n    import rclpy\n")
    edges, external = import_graph(pkg)
    assert edges["clothfold_ros.lookup.a"] == {"clothfold_ros.lookup.b"}
    assert find_cycle(edges) in (["clothfold_ros.lookup.a", "clothfold_ros.lookup.b", "clothfold_ros.lookup.a"],
                                 ["clothfold_ros.lookup.b", "clothfold_ros.lookup.a", "clothfold_ros.lookup.b"])
    assert external["clothfold_ros.lookup.b"] == {"json", "rclpy"}
    assert is_ros("geometry_msgs") and is_ros("rcl_interfaces") and not is_ros("numpy")


def test_only_the_commands_import_the_commands(graph):
    """Layers: cli/ (commands, launcher) on top of nodes/ on top of the core; nothing below
    cli/ imports it (fold_planner_node reads resources from nodes/resources, not the launcher)."""
    edges, _ = graph
    up = sorted(f"{m} -> {n}" for m, ns in edges.items() if not m.startswith("clothfold_ros.cli")
                for n in ns if n.startswith("clothfold_ros.cli"))
    assert not up, "imports of cli/ from below it:\n" + "\n".join(up)
    assert "clothfold_ros.nodes.resources" in edges["clothfold_ros.nodes.fold_planner_node"]
    assert "clothfold_ros.nodes.backends" in edges["clothfold_ros.cli.launcher"]
