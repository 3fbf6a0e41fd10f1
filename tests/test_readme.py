"""The example code of README.md and docs/algorithm.md runs as written."""
from __future__ import annotations

from markdown_examples import (
    _run_python_blocks,  # shared with tests/test_docs_examples.py
)


def test_readme_python_examples_run() -> None:
    namespace = _run_python_blocks("README.md")
    # the composing example ends with a curriculum step on the merge trajectory
    assert 0 <= namespace["selection"].subgoal < namespace["curriculum"].length


def test_algorithm_page_python_examples_run() -> None:
    """Every python block of docs/algorithm.md runs as is."""
    namespace = _run_python_blocks("docs/algorithm.md")
    # the last block (one iteration and the rounds) ends with joint SAC + meta updates and a subgoal step:
    # the meta-gradient reached the reward network, and the matching reward follows the curriculum
    assert namespace["out"]["meta_grad_norm"] > 0
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in namespace["reward_net"].parameters())
    assert namespace["matching"].subgoal == namespace["selection"].subgoal >= namespace["selection"].previous
