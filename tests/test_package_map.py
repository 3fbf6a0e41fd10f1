"""docs/package-map.md names every package folder of ``torchrl_csirl/`` (a directory with an ``__init__.py``), and
every folder it names exists."""
from __future__ import annotations

import os
import re

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PAGE = os.path.join(ROOT, "docs", "package-map.md")


def package_folders() -> set[str]:
    """``torchrl_csirl/<path>/`` of every directory of the package that holds an ``__init__.py``."""
    found = set()
    for folder, dirs, files in os.walk(os.path.join(ROOT, "torchrl_csirl")):
        dirs[:] = [d for d in dirs if d != "__pycache__"]
        if "__init__.py" in files:
            found.add(os.path.relpath(folder, ROOT).replace(os.sep, "/") + "/")
    return found


def named_folders(text: str) -> set[str]:
    """The folders of the package a page names as ``torchrl_csirl/<path>/`` in backticks.

    Examples:
        >>> sorted(named_folders("| `torchrl_csirl/tasks/` | `torchrl_csirl/run/config.py` ... `methods/config/` |"))
        ['torchrl_csirl/tasks/']
    """
    return set(re.findall(r"`(torchrl_csirl/(?:[\w.-]+/)*)`", text))


def _page() -> str:
    with open(PAGE, encoding="utf-8") as f:
        return f.read()


def test_every_package_folder_is_on_the_page():
    missing = package_folders() - named_folders(_page())
    assert not missing, f"docs/package-map.md does not name: {sorted(missing)}"


def test_every_folder_the_page_names_exists():
    absent = [f for f in named_folders(_page()) if not os.path.isdir(os.path.join(ROOT, f))]
    assert not absent, f"docs/package-map.md names folders that do not exist: {absent}"


def test_the_page_is_in_the_site_navigation():
    with open(os.path.join(ROOT, "mkdocs.yml"), encoding="utf-8") as f:
        assert "package-map.md" in f.read()
