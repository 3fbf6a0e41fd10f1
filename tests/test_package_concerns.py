"""Each module of ``torchrl_csirl`` holds the concerns its folder is for, and imports only the layers below it.

Four concerns, each seen in a module's source (:mod:`ast`, function bodies included):

* ``schema``: a configuration schema, a class field declared with ``option(...)``;
* ``building``: a run's parts built from a configuration: a TorchRL collector class imported to construct
  one, or the run layer's builders (``run.collection``, ``run.assembly``, ``run.builders``, ``run.lifecycle``,
  ``run.final``) used;
* ``loop``: the training loop, a class with a ``train`` method;
* ``plotting``: ``matplotlib`` imported.

:data:`ALLOWED` gives each folder (or module; the longest matching path wins) the concerns its modules may
hold. Only ``methods/`` holds two: a method module is its configuration sections and the builders that read
them, so that one method lies in one file (the rest of the run is shared in ``run/``); the scripts start runs
through the run layer's builders and hold nothing else. :data:`FORBIDDEN`
gives each folder the packages it may not import: the components below the run layer take plain arguments,
the run layer finds the methods by name and never imports them, the pictures stay in
``analysis/visualization``.
"""
from __future__ import annotations

import ast
import os

import pytest
from package_imports import PACKAGE_DIR, ROOT, import_from_target, package_modules

#: folder or module under ``torchrl_csirl/`` -> the concerns its modules may hold
ALLOWED: dict[str, frozenset[str]] = {
    "": frozenset(),  # the package's own small modules: _compat, _paths, _moved, ...
    "hyperparameters.py": frozenset({"schema"}),
    "objectives": frozenset(), "transforms": frozenset(), "curriculum": frozenset(), "modules": frozenset(),
    "data": frozenset(), "tasks": frozenset(),
    "trainers": frozenset({"loop"}),
    "run": frozenset({"building"}),
    "run/config.py": frozenset({"schema"}),
    "run/task_schemas.py": frozenset({"schema"}),
    "methods": frozenset({"schema", "building"}),
    "analysis": frozenset(),
    "analysis/visualization": frozenset({"plotting"}),
    "sweep": frozenset(),
    "scripts": frozenset({"building"}),  # the command lines: each starts a run through the run layer
}

_COMPONENT_LIMITS = ("torchrl_csirl.run", "torchrl_csirl.methods", "torchrl_csirl.analysis", "torchrl_csirl.sweep",
                     "torchrl_csirl.scripts", "matplotlib")
#: folder or module -> the import prefixes its modules may not use (the longest matching path wins)
FORBIDDEN: dict[str, tuple[str, ...]] = {
    "": ("torchrl_csirl.methods", "torchrl_csirl.sweep", "torchrl_csirl.scripts", "matplotlib"),
    "objectives": _COMPONENT_LIMITS, "transforms": _COMPONENT_LIMITS, "curriculum": _COMPONENT_LIMITS,
    "modules": _COMPONENT_LIMITS, "data": _COMPONENT_LIMITS, "tasks": _COMPONENT_LIMITS, "trainers": _COMPONENT_LIMITS,
    "run": ("torchrl_csirl.methods", "torchrl_csirl.sweep", "torchrl_csirl.scripts", "matplotlib"),
    "run/config.py": ("torchrl_csirl.methods", "torchrl_csirl.sweep", "torchrl_csirl.scripts", "torchrl_csirl.trainers",
                      "torchrl_csirl.run.collection", "torchrl_csirl.run.assembly", "matplotlib"),
    "methods": ("torchrl_csirl.sweep", "torchrl_csirl.scripts", "matplotlib"),
    "analysis": ("torchrl_csirl.methods", "torchrl_csirl.sweep", "torchrl_csirl.scripts", "torchrl_csirl.trainers"),
    "sweep": ("torchrl_csirl.scripts", "matplotlib"),
    "scripts": ("matplotlib",),
    "__main__.py": ("matplotlib",),  # ``python -m torchrl_csirl``: the command line's entry
}

_COLLECTORS = {"Collector", "SyncDataCollector", "MultiSyncDataCollector", "MultiaSyncDataCollector", "aSyncDataCollector"}
_BUILDERS = {f"torchrl_csirl.run.{m}" for m in ("collection", "assembly", "builders", "lifecycle", "final")}


def _imports(tree: ast.Module, module: str, is_package: bool) -> list[tuple[str, str | None, int]]:
    """``(module, imported name or None, line)`` of every import statement of the module."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(alias.name, None, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            target = import_from_target(node, module, is_package)
            found += [(target, alias.name, node.lineno) for alias in node.names]
    return found


def concerns(source: str, module: str = "torchrl_csirl.x", is_package: bool = False) -> set[str]:
    """The concerns (the module docstring's four) that ``source`` holds.

    Examples:
        >>> sorted(concerns("import matplotlib.figure\\nclass C:\\n    a: int = option(1)\\n"))
        ['plotting', 'schema']
        >>> sorted(concerns("from torchrl.collectors import Collector\\nclass T:\\n    def train(self): ..."))
        ['building', 'loop']
        >>> concerns("from torchrl.collectors import BaseCollector")  # a type, nothing built
        set()
    """
    tree = ast.parse(source)
    found = set()
    for name, imported, _ in _imports(tree, module, is_package):
        if name.split(".")[0] == "matplotlib":
            found.add("plotting")
        if (name.startswith("torchrl.collectors") and imported in _COLLECTORS) or name in _BUILDERS or (
                name == "torchrl_csirl.run" and imported in {m.rsplit(".", 1)[1] for m in _BUILDERS}):
            found.add("building")
    for node in ast.walk(tree):
        if isinstance(node, ast.ClassDef):
            for statement in node.body:
                value = getattr(statement, "value", None)
                if isinstance(statement, (ast.AnnAssign, ast.Assign)) and isinstance(value, ast.Call) and (
                        getattr(value.func, "id", None) == "option"):
                    found.add("schema")
                if isinstance(statement, ast.FunctionDef) and statement.name == "train":
                    found.add("loop")
    return found


def _rule(table: dict, path: str):
    """``table``'s entry for the package file ``path`` (relative to ``torchrl_csirl/``): its longest matching key."""
    keys = [k for k in table if k == "" or path == k or path.startswith(k.rstrip("/") + "/")]
    return table[max(keys, key=len)]


MODULES = sorted(package_modules().items())


@pytest.mark.parametrize("module, path", MODULES, ids=[m for m, _ in MODULES])
def test_a_module_holds_only_its_folders_concerns(module, path):
    relative = os.path.relpath(path, PACKAGE_DIR).replace(os.sep, "/")
    with open(path, encoding="utf-8") as f:
        held = concerns(f.read(), module, path.endswith("__init__.py"))
    extra = held - _rule(ALLOWED, relative)
    assert not extra, f"{relative} holds {sorted(extra)}, which its folder does not (ALLOWED: {sorted(_rule(ALLOWED, relative))})"


@pytest.mark.parametrize("module, path", MODULES, ids=[m for m, _ in MODULES])
def test_a_module_imports_only_the_layers_it_may(module, path):
    relative = os.path.relpath(path, PACKAGE_DIR).replace(os.sep, "/")
    with open(path, encoding="utf-8") as f:
        tree = ast.parse(f.read(), path)
    forbidden = _rule(FORBIDDEN, relative)
    bad = [f"{os.path.relpath(path, ROOT)}:{line}: {name}" for name, _, line in _imports(tree, module, path.endswith("__init__.py"))
           if any(name == p or name.startswith(p + ".") for p in forbidden)]
    assert not bad, "imports its folder may not use:\n" + "\n".join(bad)


def test_the_tables_name_folders_that_exist():
    for key in set(ALLOWED) | set(FORBIDDEN):
        assert key == "" or os.path.exists(os.path.join(PACKAGE_DIR, key)), key


def test_the_rules_catch_a_mixed_module():
    plotting_run_module = "import matplotlib.pyplot as plt\nfrom torchrl_csirl.run.assembly import Run\n"
    assert concerns(plotting_run_module) - _rule(ALLOWED, "run/final.py") == {"plotting"}
    assert "loop" not in _rule(ALLOWED, "methods/csirl.py") and "schema" not in _rule(ALLOWED, "trainers/trainer.py")
    assert "torchrl_csirl.methods" in _rule(FORBIDDEN, "run/recipes.py")
