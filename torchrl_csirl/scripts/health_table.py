"""How often each health check flags failed runs and succeeded runs, from recorded reports.

``torchrl-csirl health-table <record dir> [<record dir> ...] [--bar 0.6] [--held-out] [--runs]``

A record (``docs/runs/<group>/<cell>``, ``torchrl-csirl record`` keeps it) holds the run's ``health.json`` and its
``summary.json``. A run *succeeded* when its final test's score reaches ``--bar`` (default :data:`BAR`):

* on a driving scene, the expert-normalised test accomplish rate (``normalized_accomplish_rate``), the figure every
  driving table reports;
* else the test return over the expert's where the task has an expert record (locomotion: ``<group>/<task>-expert-s*``
  beside the records, e.g. ``docs/runs/mujoco/halfcheetah-expert-s0``), the figure the locomotion table reports;
* else the test's success rate (a goal task's, AntMaze's, PointMaze's: the share of its 50 test episodes that reach
  the goal), else its accomplish rate.

The default bar, 0.6, puts every recorded run the pages call a failure below it (the highest, PointMaze U-maze with
one demonstration, seed 0: 0.52, "a failed run" on the own-task page) and the goal-conditioned runs on PointMaze
Medium, at BC's level (0.64), at or above it, apart from CSIRL-B's seed 0 (0.58).

``--held-out`` leaves out the runs that set a threshold (:func:`torchrl_csirl.analysis.diagnostics.calibration_runs`): the
table of runs the report was not tuned on. The last line is JSON; the Markdown tables go to stderr.
"""
from __future__ import annotations

import argparse
import glob
import json
import os
import sys
from typing import Any

from torchrl_csirl.analysis.diagnostics import HEALTH_FILE, calibration_runs

__all__ = ["flag_counts", "flag_table", "held_out_table", "main", "read_record", "read_records", "run_score", "runs_table"]

#: the score from which a run counts as succeeded (see the module's docstring)
BAR = 0.6


def expert_return(record: str, scenario: str) -> float | None:
    """The mean test return of the expert records of ``scenario`` beside ``record`` (``<root>/*/<scenario>-expert-s*``,
    ``<root>`` the folder above the record's group); None without one."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(record)))
    values = []
    for path in sorted(glob.glob(os.path.join(root, "*", f"{scenario}-expert-s*", "summary.json"))):
        with open(path, encoding="utf-8") as f:
            summary = json.load(f)
        if summary.get("method") == "expert" and summary.get("return") is not None:
            values.append(float(summary["return"]))
    mean = sum(values) / len(values) if values else None
    return mean if mean is not None and mean > 0 else None


def run_score(summary: dict[str, Any], record: str) -> tuple[float | None, str]:
    """A run's score and what it is (see the module's docstring).

    Examples:
        >>> run_score({"scenario": "PointMaze_UMaze-v3", "success_rate": 0.96}, "/nowhere/group/cell")
        (0.96, 'success rate')
        >>> run_score({"scenario": "merge", "accomplish_rate": 0.8}, "/nowhere/group/cell")
        (0.8, 'accomplish rate')
        >>> run_score({"scenario": "merge", "accomplish_rate": 0.8, "normalized_accomplish_rate": 0.9}, "/nowhere/g/c")
        (0.9, 'normalized accomplish rate')
    """
    if summary.get("normalized_accomplish_rate") is not None:
        return float(summary["normalized_accomplish_rate"]), "normalized accomplish rate"
    expert = expert_return(record, str(summary.get("scenario")))
    if expert is not None and summary.get("return") is not None:
        return float(summary["return"]) / expert, "return over the expert's"
    for key in ("success_rate", "accomplish_rate"):
        if summary.get(key) is not None:
            return float(summary[key]), key.replace("_", " ")
    return None, "no test score"


def read_record(record: str, bar: float = BAR) -> dict[str, Any] | None:
    """One record's checks and outcome: ``record``, ``score``, ``metric``, ``succeeded`` and ``checks`` (each check's
    name to its ``ok``: False flagged, True in range, None too little to say); None without a report or a summary."""
    paths = [os.path.join(record, name) for name in (HEALTH_FILE, "summary.json")]
    if not all(os.path.isfile(p) for p in paths):
        return None
    with open(paths[0], encoding="utf-8") as f:
        checks = {c["name"]: c.get("ok") for c in json.load(f).get("checks", []) if c.get("name")}
    with open(paths[1], encoding="utf-8") as f:
        score, metric = run_score(json.load(f), record)
    return {"record": os.path.normpath(record), "score": score, "metric": metric,
            "succeeded": score is not None and score >= bar, "checks": checks}


def flag_counts(rows: list[dict[str, Any]]) -> dict[str, dict[str, int]]:
    """Per check: how many failed and succeeded runs it flags (``failed_flagged``, ``succeeded_flagged``) of those it
    answered (``failed``, ``succeeded``: in range or flagged), and the runs it had too little to say on or did not
    make (an older report: ``unanswered``).

    Examples:
        >>> rows = [{"succeeded": False, "checks": {"a": False}}, {"succeeded": True, "checks": {"a": True, "b": None}}]
        >>> flag_counts(rows)["a"], flag_counts(rows)["b"]["unanswered"]
        ({'failed': 1, 'failed_flagged': 1, 'succeeded': 1, 'succeeded_flagged': 0, 'unanswered': 0}, 2)
    """
    names = sorted({name for row in rows for name in row["checks"]})
    counts = {}
    for name in names:
        count = {"failed": 0, "failed_flagged": 0, "succeeded": 0, "succeeded_flagged": 0, "unanswered": 0}
        for row in rows:
            ok = row["checks"].get(name)
            if ok is None:
                count["unanswered"] += 1
                continue
            side = "succeeded" if row["succeeded"] else "failed"
            count[side] += 1
            count[f"{side}_flagged"] += ok is False
        counts[name] = count
    return counts


def _share(flagged: int, answered: int) -> str:
    return f"{flagged} of {answered}" + (f" ({flagged / answered:.0%})" if answered else "")


def flag_table(counts: dict[str, dict[str, int]], rows: list[dict[str, Any]], bar: float) -> str:
    """The Markdown table of :func:`flag_counts`."""
    failed = sum(not r["succeeded"] for r in rows)
    lines = [f"| check | flags failed runs ({failed}) | flags succeeded runs ({len(rows) - failed}, score >= {bar:g}) "
             "| too little to say, or not made |", "|---|---|---|---|"]
    for name, c in counts.items():
        lines.append(f"| `{name}` | {_share(c['failed_flagged'], c['failed'])} | "
                     f"{_share(c['succeeded_flagged'], c['succeeded'])} | {c['unanswered']} |")
    return "\n".join(lines)


def runs_table(rows: list[dict[str, Any]]) -> str:
    """One line per run: its score, outcome and flagged checks."""
    lines = ["| record | score | outcome | flagged |", "|---|---|---|---|"]
    for r in rows:
        score = "-" if r["score"] is None else f"{r['score']:.2f} ({r['metric']})"
        flagged = ", ".join(f"`{n}`" for n, ok in r["checks"].items() if ok is False) or "-"
        lines.append(f"| {r['record']} | {score} | {'succeeded' if r['succeeded'] else 'failed'} | {flagged} |")
    return "\n".join(lines)


def _in_calibration(record: str, calibration: set[str]) -> bool:
    parts = os.path.normpath(os.path.abspath(record)).split(os.sep)
    return "/".join(parts[-2:]) in calibration


def held_out_table(patterns: list[str], bar: float = BAR) -> str:
    """The flag table of the records that ``patterns`` (globs, e.g. ``docs/runs/health-*/*``) match, the calibration
    set left out: the table the own-task page prints under ``<!-- held-out-table: patterns -->``.

    Examples:
        >>> held_out_table(["/nowhere/*/*"]).splitlines()[0]
        '| check | flags failed runs (0) | flags succeeded runs (0, score >= 0.6) | too little to say, or not made |'
    """
    records = sorted({r for pattern in patterns for r in glob.glob(pattern)})
    rows, _ = read_records(records, bar, held_out=True)
    return flag_table(flag_counts(rows), rows, bar)


def read_records(records: list[str], bar: float = BAR, held_out: bool = False) -> tuple[list[dict[str, Any]], list[str]]:
    """:func:`read_record` of each record with a report (the calibration set left out where ``held_out``), and the
    records left out."""
    calibration = set(calibration_runs()) if held_out else set()
    left_out = [r for r in records if _in_calibration(r, calibration)]
    rows = [row for row in (read_record(r, bar) for r in records if r not in left_out) if row is not None]
    return rows, left_out


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Reads each record; prints the tables (stderr) and the JSON line; returns what the JSON line holds."""
    parser = argparse.ArgumentParser(prog="torchrl-csirl health-table", description=__doc__.splitlines()[0])
    parser.add_argument("records", nargs="+", help="record directories (docs/runs/<group>/<cell>)")
    parser.add_argument("--bar", type=float, default=BAR, help=f"the score from which a run succeeded (default {BAR})")
    parser.add_argument("--held-out", action="store_true", help="leave out the runs that set a threshold")
    parser.add_argument("--runs", action="store_true", help="also print one line per run")
    args = parser.parse_args(argv)
    rows, left_out = read_records(args.records, args.bar, args.held_out)
    counts = flag_counts(rows)
    print(flag_table(counts, rows, args.bar), file=sys.stderr)
    if left_out:
        print(f"\n{len(left_out)} record(s) left out: they set a threshold (the calibration set)", file=sys.stderr)
    if args.runs:
        print("\n" + runs_table(rows), file=sys.stderr)
    result = {"bar": args.bar, "records": len(rows), "succeeded": sum(r["succeeded"] for r in rows),
              "left_out": left_out, "checks": counts, "rows": rows}
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
