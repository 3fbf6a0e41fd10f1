"""No two modules of ``torchrl_csirl`` import each other, directly or through others, when the package loads.

A finer view than :mod:`tests.test_package_layout` (which checks the subpackages): here every
module is a node. The graph is static, read with :mod:`ast`; its rules:

* Only the imports that run when a module is loaded count: the statements of the module's body,
  including those under a module-level ``if`` / ``try`` / ``with`` and in class bodies. Imports
  inside functions (they run on call, after every module has loaded) and under
  ``if TYPE_CHECKING:`` (they never run) do not.
* ``import torchrl_csirl.a.b`` and ``from torchrl_csirl.a import b`` reach the module ``a.b`` when
  it exists, else the module (or package) ``a``; relative imports are resolved. A package is its
  ``__init__.py``.
* Importing a module also runs its enclosing packages' ``__init__``, so an import also reaches each
  enclosing package of its target, except the importing module's own enclosing packages: those are
  already loading when it runs, and reaching them is no new edge.
* An explicit import of an enclosing package (``from torchrl_csirl.tasks import X`` inside
  ``torchrl_csirl.tasks.foo``) is an edge like any other: that package's ``__init__`` is half-run at
  that moment, so ``X`` exists only if the ``__init__`` bound it before importing ``foo``, a circle
  that works by the order of the lines. Import ``X`` from the module that defines it.

The test fails naming every strongly connected component of more than one module and, for each,
the edges (``file:line``) that close it.

A second test applies the same rules with the imports inside functions counted too: moving one
import of a circle into a function makes the package load, but leaves the two modules needing each
other (the circle of five ``envs`` modules of issue 89 was closed by three such imports). A
function-level import that closes no circle (a heavy or optional dependency loaded on use) is fine.
"""
from __future__ import annotations

import ast
import os
from collections import defaultdict

from package_imports import ROOT, import_from_target, package_modules

#: ``module -> imported module -> ["file:line", ...]``
Graph = dict[str, dict[str, list[str]]]


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def load_time_imports(tree: ast.Module, in_functions: bool = False) -> list[ast.Import | ast.ImportFrom]:
    """The import statements that run when the module is loaded (see the module's docstring); with
    ``in_functions``, also those of its functions (``TYPE_CHECKING`` blocks stay out).

    Examples:
        >>> tree = ast.parse("import a\\nif TYPE_CHECKING:\\n    import b\\nelse:\\n    import c\\n"
        ...                  "def f():\\n    import d\\nclass K:\\n    import e")
        >>> [n.names[0].name for n in load_time_imports(tree)]
        ['a', 'c', 'e']
        >>> [n.names[0].name for n in load_time_imports(tree, in_functions=True)]
        ['a', 'c', 'd', 'e']
    """
    found: list[ast.Import | ast.ImportFrom] = []

    def visit(statements: list[ast.stmt]) -> None:
        for node in statements:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                found.append(node)
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                if in_functions:
                    visit(node.body)
            elif isinstance(node, ast.If) and _is_type_checking(node.test):
                visit(node.orelse)
            else:
                for name in ("body", "orelse", "finalbody"):
                    visit(getattr(node, name, []))
                for handler in getattr(node, "handlers", []):
                    visit(handler.body)

    visit(tree.body)
    return found


def imported_modules(node: ast.Import | ast.ImportFrom, module: str, is_package: bool, known: set[str]) -> list[str]:
    """The package modules an import statement of ``module`` loads by name (enclosing packages aside).

    Examples:
        >>> known = {"p", "p.a", "p.a.b", "p.c"}
        >>> imported_modules(ast.parse("from p.a import b, X").body[0], "p.c", False, known)
        ['p.a.b', 'p.a']
        >>> imported_modules(ast.parse("from .a import X").body[0], "p.c", False, known)
        ['p.a']
        >>> imported_modules(ast.parse("import os").body[0], "p.c", False, known)
        []
    """
    if isinstance(node, ast.Import):
        return [_nearest(alias.name, known) for alias in node.names if _nearest(alias.name, known)]
    target = import_from_target(node, module, is_package)
    found = [f"{target}.{alias.name}" for alias in node.names if f"{target}.{alias.name}" in known]
    if len(found) < len(node.names) and _nearest(target, known):  # a name defined in ``target``
        found.append(_nearest(target, known))
    return list(dict.fromkeys(found))


def _nearest(name: str, known: set[str]) -> str | None:
    """``name``, or its closest enclosing module that exists (``p.a.X`` -> ``p.a``); None outside the package."""
    parts = name.split(".")
    while parts:
        if ".".join(parts) in known:
            return ".".join(parts)
        parts.pop()
    return None


def _enclosing(name: str) -> list[str]:
    parts = name.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


def import_graph(in_functions: bool = False) -> Graph:
    """The load-time import graph between the package's modules (the module docstring's rules);
    ``in_functions``: with the imports inside functions."""
    modules = package_modules()
    known = set(modules)
    graph: Graph = defaultdict(lambda: defaultdict(list))
    for module, path in sorted(modules.items()):
        with open(path, encoding="utf-8") as f:
            tree = ast.parse(f.read(), path)
        own = set(_enclosing(module))
        for node in load_time_imports(tree, in_functions):
            for target in imported_modules(node, module, path.endswith("__init__.py"), known):
                reached = [target] + [p for p in _enclosing(target) if p in known and p not in own]
                for name in reached:
                    where = f"{os.path.relpath(path, ROOT)}:{node.lineno}"
                    if name != module and where not in graph[module][name]:
                        graph[module][name].append(where)
    return graph


def circles(graph: Graph) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan), each sorted, in sorted order.

    Examples:
        >>> circles({"a": {"b": []}, "b": {"c": []}, "c": {"a": []}, "d": {"a": []}})
        [['a', 'b', 'c']]
        >>> circles({"a": {"b": []}, "b": {}})
        []
    """
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph.get(node, {})):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return sorted(found)


def describe_circle(graph: Graph, component: list[str]) -> str:
    """A circle's modules and the edges between them, one ``a -> b: file:line`` a line."""
    members = set(component)
    edges = [f"    {a} -> {b}: {', '.join(graph[a][b])}"
             for a in component for b in sorted(graph.get(a, {})) if b in members]
    return f"  {', '.join(component)}\n" + "\n".join(edges)


def test_the_graph_sees_load_time_imports():
    graph = import_graph()
    assert "torchrl_csirl.objectives.ensemble_sac" in graph["torchrl_csirl.objectives.csirl_learner"]
    assert "torchrl_csirl.tasks" in graph["torchrl_csirl.methods.csirl"]  # from torchrl_csirl.tasks import ...
    assert "torchrl_csirl.tasks.spec" in graph["torchrl_csirl.tasks"]  # a package reaches what its __init__ imports


def _assert_no_circle(graph: Graph, what: str) -> None:
    found = circles(graph)
    assert not found, f"import circles (strongly connected components of {what}):\n" + "\n".join(
        describe_circle(graph, c) for c in found)


def test_the_package_has_no_import_circle():
    _assert_no_circle(import_graph(), "the load-time import graph")


def test_no_function_level_import_closes_a_circle():
    _assert_no_circle(import_graph(in_functions=True), "the import graph with the imports inside functions")
