"""MkDocs hook: the configuration reference, generated from the recipes' typed schemas at build time.

A page asks for a schema's table with a marker on a line of its own::

    <!-- config-reference: torchrl_csirl.methods.csirl:CSIRLHighwayConfig -->

``module:Class`` is imported (the schemas live in :mod:`torchrl_csirl.run`) and replaced by a
table of every key: its type and allowed values, its default and its help, read from the
dataclasses by ``torchrl_csirl.run.config.describe_rows`` — the same
function behind every script's ``--help``, so the page can never drift from the code.

``<!-- scene-defaults: torchrl_csirl.methods.csirl -->`` is replaced by the table of the scenarios' own defaults
(``scene/<scenario>.yaml`` under that module's ``CONFIG_DIR``, or under another folder it names:
``torchrl_csirl.methods.csirl:TASK_CONFIG_DIR``), read by ``torchrl_csirl.run.config.scene_defaults``.
"""
from __future__ import annotations

import importlib
import re

_MARKER = re.compile(r"^<!-- config-reference: ([\w.]+):(\w+) -->$", flags=re.M)
_SCENES = re.compile(r"^<!-- scene-defaults: ([\w.]+)(?::(\w+))? -->$", flags=re.M)


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _import(module: str):
    return importlib.import_module(module)


def config_table(module: str, name: str) -> str:
    """The Markdown table of every key of ``module:name``."""
    schema = getattr(_import(module), name)
    from torchrl_csirl.run.config import describe_rows

    rows = ["| key | default | accepts | meaning |", "|---|---|---|---|"]
    for row in describe_rows(schema):
        rows.append(f"| `{row.key}` | `{_cell(row.default)}` | {_cell(row.allowed)} | {_cell(row.help)} |")
    return "\n".join(rows)


def scene_table(module: str, folder: str | None = None) -> str:
    """The Markdown table of the scenario defaults under ``module.CONFIG_DIR`` (or ``module.<folder>``)."""
    from torchrl_csirl.run.config import scene_defaults

    rows = ["| scenario | its defaults |", "|---|---|"]
    for scenario, values in scene_defaults(getattr(_import(module), folder or "CONFIG_DIR")).items():
        rows.append(f"| `{scenario}` | " + ", ".join(f"`{k}={_cell(str(v).lower() if isinstance(v, bool) else str(v))}`"
                                                     for k, v in values.items()) + " |")
    return "\n".join(rows)


def on_page_markdown(markdown: str, page, config, files) -> str:  # noqa: ARG001 - MkDocs hook signature
    """Replaces every config-reference and scene-defaults marker of a page by its generated table."""
    markdown = _MARKER.sub(lambda m: config_table(m.group(1), m.group(2)), markdown)
    return _SCENES.sub(lambda m: scene_table(m.group(1), m.group(2)), markdown)
