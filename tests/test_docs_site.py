"""The documentation site: it builds, its API reference names every public object, and its
configuration reference lists every key of every recipe (generated, so it cannot drift).

CI builds the site in strict mode (`.ci/run`); these tests build it once more, non-strict, to read
what was generated.
"""
from __future__ import annotations

import importlib
import os
import re
import subprocess
import sys
import zlib

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SUBPACKAGES = ("objectives", "transforms", "curriculum", "data", "tasks", "tasks.robotics", "modules",
               "trainers", "analysis.visualization", "run", "analysis.diagnostics")
pytest.importorskip("mkdocs", reason="the docs extra (pip install -e '.[docs]')")


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> str:
    out = str(tmp_path_factory.mktemp("site"))
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--quiet", "--site-dir", out],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out


def _inventory(site: str) -> set[str]:
    with open(os.path.join(site, "objects.inv"), "rb") as f:
        data = f.read()
    body = zlib.decompress(data.split(b"\n", 4)[4]).decode()
    return {line.split()[0] for line in body.splitlines() if line.strip()}


def test_api_reference_has_every_public_name(site: str) -> None:
    names = _inventory(site)
    missing = []
    for sub in SUBPACKAGES:
        module = importlib.import_module(f"torchrl_csirl.{sub}")
        for name in module.__all__:
            # a function named as its own module is documented under the module's path
            candidates = (f"torchrl_csirl.{sub}.{name}", f"torchrl_csirl.{sub}.{name}.{name}")
            if not any(c in names for c in candidates):
                missing.append(f"torchrl_csirl.{sub}.{name}")
    assert not missing, f"not in the API reference: {missing}"


def test_configuration_reference_lists_every_key(site: str) -> None:
    from torchrl_csirl.run import recipe_schemas
    from torchrl_csirl.run.config import describe_rows

    with open(os.path.join(ROOT, "docs", "configuration.md"), encoding="utf-8") as f:
        markers = re.findall(r"<!-- config-reference: ([\w.]+):(\w+) -->", f.read())
    missing = set(recipe_schemas()) - {f"{m}:{n}" for m, n in markers}
    assert not missing, f"recipes without a table in docs/configuration.md: {missing}"
    with open(os.path.join(site, "configuration", "index.html"), encoding="utf-8") as f:
        html = f.read()
    assert "config-reference" not in html, "a marker was left unexpanded"
    for module, name in markers:
        schema = getattr(importlib.import_module(module), name)
        keys = [row.key for row in describe_rows(schema)]
        assert keys, f"{module}:{name} has no keys"
        absent = [k for k in keys if f"<code>{k}</code>" not in html]
        assert not absent, f"{module}:{name}: keys missing from the page: {absent}"
