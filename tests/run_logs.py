"""Reading a run directory's logs in tests (shared by the interrupt and sweep-stop tests)."""
from __future__ import annotations

import json
import os


def metrics_rows(run_dir: str) -> list[dict]:
    """The rows of ``<run_dir>/metrics.jsonl`` (none before the first is logged)."""
    path = os.path.join(run_dir, "metrics.jsonl")
    if not os.path.exists(path):
        return []
    with open(path) as f:
        return [json.loads(line) for line in f if line.strip()]
