"""Copy finished runs' records into the repository: ``docs/runs/<group>/<run>``.

A record is what a table, its curves and the figures quoted about a run's training are rebuilt from
(``docs/runs/README.md``):

* the run's ``summary.json``, ``config.yaml``, ``provenance.json`` (the commit, dirty flag and diff hash, package
  versions, CPU and threads it ran with: ``torchrl_csirl.run.provenance``) and ``health.json`` (its health report),
  and its ``resumes.jsonl`` where the run was resumed with changed settings; a run made before runs wrote it has no
  ``provenance.json``, and its record says ``provenance: unknown`` when it is made;
* ``metrics.jsonl`` trimmed to the evaluation rows (``frames``, ``updates``, ``round`` and the ``eval_*``
  keys: the curves of ``benchmark.py report``; the test is in the summary);
* ``rounds.csv``: one row per round of training (:func:`round_rows`): the run's position at the round's
  end, the subgoal there, and the mean over the round's batch rows of every other quantity the run logs
  (losses, ``alpha``, ``entropy``, ``r_w``'s batch mean ``intrinsic_reward_mean``, ...), with the extremes of
  those the pages bound (:data:`EXTREMES`), to 4 significant digits and at most ``max_rounds`` rows;
* the outputs of the probes kept beside the run (:data:`PROBES`): ``termination_probe.json`` (the study script
  ``docs/studies/scripts/termination_probe.py`` writes it there), ``locomotion_probe.json`` and ``outcomes.json``
  (the last line of ``docs/studies/scripts/locomotion_probe.py`` or ``torchrl-csirl outcomes``, redirected there).

Checkpoints, policies and plots stay with the run.
A run without ``summary.json`` has not finished and is refused; an existing record is kept unless
``--force``.

Usage::

    torchrl-csirl record /work/runs/mujoco/halfcheetah-dac-s0 --into docs/runs/mujoco
    torchrl-csirl record /work/runs/mujoco/hopper-*-s1 --into docs/runs/mujoco --force

Examples:
    >>> evaluation_rows([{"frames": 10, "loss_actor": 1.0}, {"frames": 20, "updates": 5, "eval_env_return": 3.0}])
    [{'frames': 20, 'updates': 5, 'eval_env_return': 3.0}]
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import os
import shutil
import sys

from torchrl_csirl.run.provenance import PROVENANCE_FILE

__all__ = ["RecordError", "evaluation_rows", "main", "read_metrics", "read_rounds", "record_run", "round_rows",
           "write_rounds"]

PROG = "torchrl-csirl record"
#: the files a record copies as they are (``resumes.jsonl`` only where it exists)
COPIED = ("summary.json", "config.yaml", PROVENANCE_FILE, "resumes.jsonl", "health.json")
#: the outputs of the probes a record copies where the run has them: ``termination_probe.py`` writes its own; the
#: others are the last line of ``locomotion_probe.py`` / ``torchrl-csirl outcomes`` redirected there;
#: ``policy_scale.json`` is the one hand-made series a record holds (docs/benchmark.md)
PROBES = ("termination_probe.json", "locomotion_probe.json", "outcomes.json", "policy_scale.json")
#: the keys of an evaluation row kept besides its ``eval_*`` metrics (a round row's position too)
ROW_KEYS = ("frames", "updates", "round")
EVALUATION_PREFIX = "eval_"
#: the per-round rows of a record
ROUNDS_FILE = "rounds.csv"
#: keys of a batch row no round row keeps: the machine's speed (the summary has the run's) and the final test's
LEFT_OUT = ("collect_fps", "updates_per_s")
LEFT_OUT_PREFIXES = (EVALUATION_PREFIX, "test_")
#: recorded once, at a round's end (its value there, not a mean): the curriculum's subgoal
ROUND_END_KEYS = ("subgoal", "subgoal_changed")
#: quantities the pages bound over batches (``r_w`` "within 5e-5 of zero", GAIL's discriminator loss "below
#: 0.001"): their smallest and largest batch value of each round as well, ``<key>_min`` and ``<key>_max``
EXTREMES = ("intrinsic_reward_mean", "loss_discriminator")
#: at most this many rows in ``rounds.csv``: a longer run's consecutive rounds are pooled a few at a time
MAX_ROUNDS = 400
SIGNIFICANT_DIGITS = 4


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


def _number(value: object) -> float | int | None:
    """A logged value as a number: the logger writes a non-finite float as a string (``"nan"``)."""
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, (int, float)):
        return value
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return None
    return None


def _rounded(value: float | int) -> float | int:
    """``value`` to :data:`SIGNIFICANT_DIGITS` significant digits (an integer as it is)."""
    if isinstance(value, int) or not math.isfinite(value):
        return value
    return float(f"{value:.{SIGNIFICANT_DIGITS}g}")


def _pooled(batches: list[dict]) -> dict:
    """One round row from the batch rows of one round (or of a few consecutive ones)."""
    last = batches[-1]
    row: dict = {**{k: last[k] for k in ROW_KEYS if k in last}, "batches": len(batches)}
    values: dict[str, list] = {}
    for batch in batches:
        for key, value in batch.items():
            if key in ROW_KEYS or key in LEFT_OUT or key.startswith(LEFT_OUT_PREFIXES):
                continue
            number = _number(value)
            if number is not None:
                values.setdefault(key, []).append(number)
    for key, series in values.items():
        if key in ROUND_END_KEYS:
            row[key] = series[-1]
            continue
        row[key] = _rounded(sum(series) / len(series))
        if key in EXTREMES:
            row[f"{key}_min"], row[f"{key}_max"] = _rounded(min(series)), _rounded(max(series))
    return row


def round_rows(rows: list[dict], max_rounds: int = MAX_ROUNDS) -> list[dict]:
    """The per-round rows of a record, from a run's ``metrics.jsonl`` rows.

    A batch row (one per collected batch, with its ``round``) holds the means of its updates' losses; a round's
    last batch row also what the round's end recorded (the subgoal, an evaluation). A round row holds the
    round's end (``frames``, ``updates``, ``round``), ``batches`` (how many batch rows it pools), the subgoal
    there (:data:`ROUND_END_KEYS`) and the mean over its batch rows of every other quantity logged, with the
    minimum and maximum of :data:`EXTREMES`, to :data:`SIGNIFICANT_DIGITS` significant digits. Left out: the
    evaluations (the record's ``metrics.jsonl`` keeps them whole), the final test and the timings. A run of more
    than ``max_rounds`` rounds is pooled ``k`` consecutive rounds a row (the row's position the last one's), ``k``
    the fewest that fit. A last round cut short by the budget is a row too. Repeated batches (a log resumed
    before the logger dropped the rows past the checkpoint) count once, their last copy. No row where nothing
    but the position and evaluations was logged (a record, a reference row).

    Examples:
        >>> rows = [{"frames": 100, "updates": 50, "round": 0, "collect_fps": 500.0, "alpha": 0.02},
        ...         {"frames": 200, "updates": 100, "round": 0, "alpha": 0.04, "subgoal": 3, "eval_env_return": 1.5},
        ...         {"frames": 300, "updates": 150, "round": 1, "alpha": 0.05, "intrinsic_reward_mean": 0.25},
        ...         {"frames": 300, "updates": 150, "test_env_return": 2.0}]
        >>> round_rows(rows)  # doctest: +NORMALIZE_WHITESPACE
        [{'frames': 200, 'updates': 100, 'round': 0, 'batches': 2, 'alpha': 0.03, 'subgoal': 3},
         {'frames': 300, 'updates': 150, 'round': 1, 'batches': 1, 'alpha': 0.05, 'intrinsic_reward_mean': 0.25,
          'intrinsic_reward_mean_min': 0.25, 'intrinsic_reward_mean_max': 0.25}]
        >>> [r["round"] for r in round_rows(rows, max_rounds=1)]  # two rounds pooled into one row
        [1]
    """
    if max_rounds < 1:
        raise ValueError(f"max_rounds must be >= 1, got {max_rounds}.")
    batches: dict = {}
    for row in rows:
        if "round" in row and "frames" in row:
            batches[row["frames"]] = row  # a repeated batch: its last copy
    rounds: dict = {}
    for row in sorted(batches.values(), key=lambda r: r["frames"]):
        rounds.setdefault(row["round"], []).append(row)
    groups = list(rounds.values())
    per_row = math.ceil(len(groups) / max_rounds) if groups else 1
    pooled = [_pooled([b for group in groups[i:i + per_row] for b in group]) for i in range(0, len(groups), per_row)]
    if not any(len(row) > len(ROW_KEYS) + 1 for row in pooled):
        return []
    return pooled


def write_rounds(path: str, rows: list[dict]) -> None:
    """``rows`` as CSV: one column per key (in first-seen order), empty where a round did not log it."""
    columns: dict[str, None] = {}
    for row in rows:
        columns.update(dict.fromkeys(row))
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(columns), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)


def read_rounds(record: str) -> list[dict[str, str]]:
    """The rows of a record's ``rounds.csv`` (strings, empty where a round did not log a column).

    Raises:
        SystemExit: naming the record when it has no ``rounds.csv`` (records before the per-round table).
    """
    path = os.path.join(record, ROUNDS_FILE)
    if not os.path.isfile(path):
        raise SystemExit(f"{record}: no {ROUNDS_FILE} (records before the per-round table have none)")
    with open(path, newline="", encoding="utf-8") as handle:
        return list(csv.DictReader(handle))


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


def record_run(run_dir: str, into: str, force: bool = False, max_rounds: int = MAX_ROUNDS) -> str:
    """Write the record of ``run_dir`` as ``<into>/<run name>``; returns the record's folder.

    Args:
        run_dir: a finished run (or a record: recording it again gives the same record).
        into: the record group, e.g. ``docs/runs/mujoco``.
        force: replace an existing record (nothing of the old one is kept).
        max_rounds: the most rows of ``rounds.csv`` (:func:`round_rows`).
    """
    run_dir = os.path.normpath(run_dir)
    if not os.path.isfile(os.path.join(run_dir, "summary.json")):
        raise RecordError(f"{run_dir} has no summary.json: the run has not finished (resume it first)")
    target = os.path.join(into, os.path.basename(run_dir))
    if os.path.exists(target) and not force:
        raise RecordError(f"{target} exists: pass --force to replace it")
    metrics = os.path.join(run_dir, "metrics.jsonl")
    logged = read_metrics(metrics) if os.path.isfile(metrics) else []
    rows, rounds = evaluation_rows(logged), round_rows(logged, max_rounds)
    os.makedirs(target, exist_ok=True)
    for name in (*COPIED, *PROBES, ROUNDS_FILE):  # a record's own rounds.csv where its rows are not logged
        source = os.path.join(run_dir, name)
        if os.path.isfile(source):
            shutil.copyfile(source, os.path.join(target, name))
        elif os.path.exists(os.path.join(target, name)):
            os.remove(os.path.join(target, name))  # a replaced record keeps no file of the old run
    with open(os.path.join(target, "metrics.jsonl"), "w") as handle:
        handle.writelines(json.dumps(row) + "\n" for row in rows)
    if rounds:
        write_rounds(os.path.join(target, ROUNDS_FILE), rounds)
    if not os.path.isfile(os.path.join(run_dir, PROVENANCE_FILE)):
        print(f"{PROG}: {target}: provenance: unknown (the run has no {PROVENANCE_FILE}: made before runs wrote it)",
              file=sys.stderr)
    return target


def main(argv: list[str] | None = None) -> int:
    """Records each run (``argv``: the command line, ``None`` for ``sys.argv[1:]``), printing each record's folder.

    Returns:
        The exit status: 1 when a run could not be recorded (one line each on stderr), else 0.
    """
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", help="finished run directories")
    parser.add_argument("--into", required=True, help="the record group, e.g. docs/runs/mujoco")
    parser.add_argument("--force", action="store_true", help="replace existing records")
    parser.add_argument("--max-rounds", type=int, default=MAX_ROUNDS,
                        help=f"the most rows of rounds.csv, longer runs pooling rounds (default {MAX_ROUNDS})")
    args = parser.parse_args(argv)
    failed = 0
    for run_dir in args.runs:
        try:
            print(record_run(run_dir, args.into, force=args.force, max_rounds=args.max_rounds))
        except RecordError as err:
            print(f"{PROG}: {err}", file=sys.stderr)
            failed += 1
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
