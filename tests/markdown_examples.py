"""Runs the ```python blocks of the Markdown pages (README.md, docs/): shared by the docs tests.

Only blocks fenced exactly as ```python run; anything else (```py, ```text, ```bash, ...) is
left alone, which is how a page shows a sketch that must not run.
"""
from __future__ import annotations

import os
import re

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

_PYTHON_BLOCK = re.compile(r"```python\n(.*?)```", flags=re.S)


def python_blocks(relative_path: str) -> list[str]:
    """The ```python blocks of a page (path relative to the repository root), in order."""
    with open(os.path.join(ROOT, relative_path), encoding="utf-8") as f:
        return _PYTHON_BLOCK.findall(f.read())


def _run_python_blocks(relative_path: str, *, shared_namespace: bool = False) -> dict:
    """Runs every python block of a Markdown page in order and returns the last namespace.

    Each block gets a fresh namespace, unless ``shared_namespace`` (then the page's blocks share
    one, as a reader running them one after the other would).
    """
    blocks = python_blocks(relative_path)
    assert blocks, f"{relative_path} has no python example"
    namespace: dict = {}
    for index, block in enumerate(blocks):
        if not shared_namespace:
            namespace = {}
        exec(compile(block, f"{relative_path} (python block {index})", "exec"), namespace)  # noqa: S102 - our own docs
    return namespace
