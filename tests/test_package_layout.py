"""The package's subpackages depend on each other one way only: no import cycle between them.

Static: every ``import`` / ``from ... import`` in ``torchrl_csirl/`` (function-level ones
included, relative ones resolved) gives an edge from the importing file's subpackage (or top-level
module, e.g. ``_compat``) to the imported one; the graph must be acyclic.
"""
from __future__ import annotations

import ast
import os
from collections import defaultdict

from package_imports import PACKAGE, PACKAGE_DIR, ROOT, import_from_target, package_modules


def _imported(node: ast.AST, module: str, is_package: bool) -> list[str]:
    """The absolute names an import statement reaches (``from a import b``: ``a`` and ``a.b``)."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    if not isinstance(node, ast.ImportFrom):
        return []
    target = import_from_target(node, module, is_package)
    return [target] + [f"{target}.{alias.name}" for alias in node.names]


def _unit(name: str) -> str | None:
    """The subpackage (or top-level module) of ``torchrl_csirl`` that ``name`` lies in."""
    parts = name.split(".")
    if parts[0] != PACKAGE or len(parts) < 2:
        return None
    unit = parts[1]
    exists = os.path.isdir(os.path.join(PACKAGE_DIR, unit)) or os.path.isfile(os.path.join(PACKAGE_DIR, unit + ".py"))
    return unit if exists else None


def import_graph() -> dict[str, dict[str, list[str]]]:
    """``unit -> imported unit -> ["file:line", ...]`` over the whole package."""
    graph: dict[str, dict[str, list[str]]] = defaultdict(lambda: defaultdict(list))
    for module, path in package_modules().items():
        source = _unit(module)
        if source is None:  # the package's own __init__
            continue
        with open(path, encoding="utf-8") as f:
            tree = ast.parse(f.read(), path)
        for node in ast.walk(tree):
            for name in _imported(node, module, path.endswith("__init__.py")):
                target = _unit(name)
                if target is not None and target != source:
                    where = f"{os.path.relpath(path, ROOT)}:{node.lineno}"
                    if where not in graph[source][target]:
                        graph[source][target].append(where)
    return graph


def find_cycle(graph: dict[str, dict[str, list[str]]]) -> list[str] | None:
    """One cycle ``[a, b, ..., a]`` of ``graph``, or None.

    Examples:
        >>> find_cycle({"a": {"b": []}, "b": {"a": []}})
        ['a', 'b', 'a']
        >>> find_cycle({"a": {"b": []}, "b": {}}) is None
        True
    """
    state: dict[str, int] = {}  # 1: on the path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, {})):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        path.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return None


def test_the_import_graph_sees_the_known_dependencies():
    graph = import_graph()
    assert "objectives" in graph["trainers"]  # module level
    assert "tasks" in graph["data"]  # a function-level import
    assert "modules" in graph["tasks"]  # the experts drive with saved networks


def test_the_subpackages_import_each_other_without_a_cycle():
    graph = import_graph()
    cycle = find_cycle(graph)
    if cycle:
        edges = "\n".join(f"  {a} -> {b}: {', '.join(graph[a][b])}" for a, b in zip(cycle, cycle[1:]))
        raise AssertionError(f"import cycle {' -> '.join(cycle)}:\n{edges}")
