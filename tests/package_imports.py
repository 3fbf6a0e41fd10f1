"""The package's modules and how an import statement names its target: shared by the import-graph tests
(:mod:`test_package_layout`, between subpackages; :mod:`test_import_graph`, between modules)."""
from __future__ import annotations

import ast
import os

PACKAGE = "torchrl_csirl"
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE_DIR = os.path.join(ROOT, PACKAGE)


def package_modules() -> dict[str, str]:
    """``dotted module name -> path`` of every ``.py`` file of the package (a package: its ``__init__.py``)."""
    modules = {}
    for folder, _, files in os.walk(PACKAGE_DIR):
        for file in sorted(files):
            if file.endswith(".py"):
                path = os.path.join(folder, file)
                parts = os.path.relpath(path, ROOT)[:-3].split(os.sep)
                modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return modules


def import_from_target(node: ast.ImportFrom, module: str, is_package: bool) -> str:
    """The absolute name of the module a ``from ... import`` of ``module`` imports from (relative ones resolved).

    Examples:
        >>> import_from_target(ast.parse("from .a import X").body[0], "p.c", False)
        'p.a'
        >>> import_from_target(ast.parse("from . import X").body[0], "p", True)
        'p'
    """
    if not node.level:
        return node.module or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[:len(base) - node.level + 1]
    return ".".join(base + ([node.module] if node.module else []))
