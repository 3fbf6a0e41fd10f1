"""MkDocs hook: the configuration reference, generated from the recipes' typed schemas at build time.

A page asks for a schema's table with a marker on a line of its own::

    <!-- config-reference: common.csirl:CSIRLHighwayConfig -->

``module:Class`` is imported with ``recipes/`` on ``sys.path`` (where the recipes' shared
configuration lives) and replaced by a table of every key: its type and allowed values, its
default and its help, read from the dataclasses by ``common.config.describe_rows`` — the same
function behind every recipe's ``--help``, so the page can never drift from the code.
"""
from __future__ import annotations

import importlib
import os
import re
import sys

_MARKER = re.compile(r"^<!-- config-reference: ([\w.]+):(\w+) -->$", flags=re.M)
_RECIPES = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "recipes")


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def config_table(module: str, name: str) -> str:
    """The Markdown table of every key of ``module:name``."""
    if _RECIPES not in sys.path:
        sys.path.insert(0, _RECIPES)
    schema = getattr(importlib.import_module(module), name)
    from common.config import describe_rows

    rows = ["| key | default | accepts | meaning |", "|---|---|---|---|"]
    for row in describe_rows(schema):
        rows.append(f"| `{row.key}` | `{_cell(row.default)}` | {_cell(row.allowed)} | {_cell(row.help)} |")
    return "\n".join(rows)


def on_page_markdown(markdown: str, page, config, files) -> str:  # noqa: ARG001 - MkDocs hook signature
    """Replaces every config-reference marker of a page by its generated table."""
    return _MARKER.sub(lambda m: config_table(m.group(1), m.group(2)), markdown)
