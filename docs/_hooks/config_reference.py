"""MkDocs hook: the configuration reference, generated from the recipes' typed schemas at build time.

A page asks for a schema's table with a marker on a line of its own::

    <!-- config-reference: common.csirl:CSIRLHighwayConfig -->

``module:Class`` is imported with ``recipes/`` on ``sys.path`` (where the recipes' shared
configuration lives) and replaced by a table of every key: its type and allowed values, its
default and its help, read from the dataclasses by ``common.config.describe_rows`` — the same
function behind every recipe's ``--help``, so the page can never drift from the code.

``<!-- scene-defaults: common.csirl -->`` is replaced by the table of the scenarios' own defaults
(``scene/<scenario>.yaml`` under that module's ``CONFIG_DIR``), read by ``common.config.scene_defaults``.
"""
from __future__ import annotations

import importlib
import os
import re
import sys

_MARKER = re.compile(r"^<!-- config-reference: ([\w.]+):(\w+) -->$", flags=re.M)
_SCENES = re.compile(r"^<!-- scene-defaults: ([\w.]+) -->$", flags=re.M)
_RECIPES = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "recipes")


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _import(module: str):
    if _RECIPES not in sys.path:
        sys.path.insert(0, _RECIPES)
    return importlib.import_module(module)


def config_table(module: str, name: str) -> str:
    """The Markdown table of every key of ``module:name``."""
    schema = getattr(_import(module), name)
    from common.config import describe_rows

    rows = ["| key | default | accepts | meaning |", "|---|---|---|---|"]
    for row in describe_rows(schema):
        rows.append(f"| `{row.key}` | `{_cell(row.default)}` | {_cell(row.allowed)} | {_cell(row.help)} |")
    return "\n".join(rows)


def scene_table(module: str) -> str:
    """The Markdown table of the scenario defaults under ``module.CONFIG_DIR``."""
    from common.config import scene_defaults

    rows = ["| scenario | its defaults |", "|---|---|"]
    for scenario, values in scene_defaults(_import(module).CONFIG_DIR).items():
        rows.append(f"| `{scenario}` | " + ", ".join(f"`{k}={_cell(str(v).lower() if isinstance(v, bool) else str(v))}`"
                                                     for k, v in values.items()) + " |")
    return "\n".join(rows)


def on_page_markdown(markdown: str, page, config, files) -> str:  # noqa: ARG001 - MkDocs hook signature
    """Replaces every config-reference and scene-defaults marker of a page by its generated table."""
    markdown = _MARKER.sub(lambda m: config_table(m.group(1), m.group(2)), markdown)
    return _SCENES.sub(lambda m: scene_table(m.group(1)), markdown)
