"""The example code of README.md and docs/ALGORITHM.md runs as written."""
from __future__ import annotations

import os
import re

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _run_python_blocks(relative_path: str) -> dict:
    """Runs every python block of a Markdown page, each in a fresh namespace; returns the last one's."""
    with open(os.path.join(ROOT, relative_path), encoding="utf-8") as f:
        blocks = re.findall(r"```python\n(.*?)```", f.read(), flags=re.S)
    assert blocks, f"{relative_path} has no python example"
    namespace: dict = {}
    for block in blocks:
        namespace = {}
        exec(compile(block, relative_path, "exec"), namespace)  # noqa: S102 - our own docs
    return namespace


def test_readme_python_examples_run() -> None:
    namespace = _run_python_blocks("README.md")
    # the composing example ends with a curriculum step on the merge trajectory
    assert 0 <= namespace["selection"].subgoal < namespace["curriculum"].length


def test_algorithm_page_python_examples_run() -> None:
    """docs/ALGORITHM.md promises that every code block on the page runs as is."""
    namespace = _run_python_blocks("docs/ALGORITHM.md")
    # the last block (section 12) ends with a mixed batch and the actor's cloning term
    assert namespace["batch"].batch_size == (64,) and namespace["logs"]["actor_bc_mse"] > 0
