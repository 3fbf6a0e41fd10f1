"""Copy finished runs' records into the repository: ``docs/runs/<group>/<run>``.

A record is what a table and its curves are rebuilt from (``docs/runs/README.md``): the run's
``summary.json`` and ``config.yaml``, its ``resumes.jsonl`` where the run was resumed with changed
settings, and its ``metrics.jsonl`` trimmed to the evaluation rows (``frames``, ``updates``,
``round`` and the ``eval_*`` keys: the curves of ``benchmark.py report``; the test is in the summary).
Checkpoints, policies and plots stay with the run.
A run without ``summary.json`` has not finished and is refused; an existing record is kept unless
``--force``.

Usage::

    python tools/record_runs.py /work/runs/mujoco/halfcheetah-dac-s0 --into docs/runs/mujoco
    python tools/record_runs.py /work/runs/mujoco/hopper-*-s1 --into docs/runs/mujoco --force

Examples:
    >>> from record_runs import evaluation_rows  # doctest: +SKIP
    >>> evaluation_rows([{"frames": 10, "loss_actor": 1.0}, {"frames": 20, "updates": 5, "eval_env_return": 3.0}])
    [{'frames': 20, 'updates': 5, 'eval_env_return': 3.0}]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys

#: the files a record copies as they are (``resumes.jsonl`` only where it exists)
COPIED = ("summary.json", "config.yaml", "resumes.jsonl")
#: the keys of an evaluation row kept besides its ``eval_*`` metrics
ROW_KEYS = ("frames", "updates", "round")
EVALUATION_PREFIX = "eval_"


class RecordError(ValueError):
    """A run that cannot be recorded (unfinished, unreadable, or already recorded)."""


def evaluation_rows(rows: list[dict]) -> list[dict]:
    """Keep the rows that hold an evaluation, and in them only its keys and the run's position."""
    kept = []
    for row in rows:
        metrics = {k: v for k, v in row.items() if k.startswith(EVALUATION_PREFIX)}
        if metrics:
            kept.append({**{k: row[k] for k in ROW_KEYS if k in row}, **metrics})
    return kept


def read_metrics(path: str) -> list[dict]:
    """The JSON rows of ``metrics.jsonl``; a line that is not JSON is an error naming it."""
    rows = []
    with open(path) as handle:
        for number, line in enumerate(handle, 1):
            if not line.strip():
                continue
            try:
                rows.append(json.loads(line))
            except json.JSONDecodeError as err:
                raise RecordError(f"{path}:{number} is not a JSON line ({err.msg})") from None
    return rows


def record_run(run_dir: str, into: str, force: bool = False) -> str:
    """Write the record of ``run_dir`` as ``<into>/<run name>``; returns the record's folder."""
    run_dir = os.path.normpath(run_dir)
    if not os.path.isfile(os.path.join(run_dir, "summary.json")):
        raise RecordError(f"{run_dir} has no summary.json: the run has not finished (resume it first)")
    target = os.path.join(into, os.path.basename(run_dir))
    if os.path.exists(target) and not force:
        raise RecordError(f"{target} exists: pass --force to replace it")
    metrics = os.path.join(run_dir, "metrics.jsonl")
    rows = evaluation_rows(read_metrics(metrics)) if os.path.isfile(metrics) else []
    os.makedirs(target, exist_ok=True)
    for name in COPIED:
        source = os.path.join(run_dir, name)
        if os.path.isfile(source):
            shutil.copyfile(source, os.path.join(target, name))
        elif os.path.exists(os.path.join(target, name)):
            os.remove(os.path.join(target, name))  # a replaced record keeps no file of the old run
    with open(os.path.join(target, "metrics.jsonl"), "w") as handle:
        handle.writelines(json.dumps(row) + "\n" for row in rows)
    return target


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="record_runs.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", help="finished run directories")
    parser.add_argument("--into", required=True, help="the record group, e.g. docs/runs/mujoco")
    parser.add_argument("--force", action="store_true", help="replace existing records")
    args = parser.parse_args(argv)
    failed = 0
    for run_dir in args.runs:
        try:
            print(record_run(run_dir, args.into, force=args.force))
        except RecordError as err:
            print(f"record_runs.py: {err}", file=sys.stderr)
            failed += 1
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
