"""Where recorded runs' curricula stood against their policies: the subgoal ahead of where the episodes end.

``python docs/studies/scripts/subgoal_lead_records.py <record dir> [<record dir> ...]``

A record's ``health.json`` (``torchrl-csirl record`` keeps it) holds the last subgoal's share of the curriculum
trajectory (``subgoal_progress``) and where the policy's probe episodes end along the demonstration
(``where_episodes_end``, median). Reports written before ``where_episodes_end`` read the subgoal do not say when the
curriculum moved on without the policy (:func:`torchrl_csirl.analysis.diagnostics.curriculum_moved_on`); this reads it from
their figures. A run probed by the current report says it itself: ``torchrl-csirl diagnose <run dir>``.

The last line is JSON; a Markdown table goes to stderr.
"""
from __future__ import annotations

import argparse
import json
import os
import sys

from torchrl_csirl.analysis.diagnostics import HEALTH_FILE, curriculum_moved_on


def read_record(record: str) -> dict[str, object] | None:
    """One record's curriculum against its policy.

    Args:
        record: a record directory (its ``health.json``).

    Returns:
        ``subgoal_share`` (the last subgoal's share of the curriculum trajectory), ``progress_median`` (where the
        probe episodes end along the demonstration), ``episodes_flagged`` (``where_episodes_end`` out of range) and
        ``curriculum_moved_on``; None for a record without a report or without both figures (a run of under three
        rounds, a report from before the checks).
    """
    path = os.path.join(record, HEALTH_FILE)
    if not os.path.isfile(path):
        return None
    with open(path, encoding="utf-8") as f:
        checks = {c.get("name"): c for c in json.load(f).get("checks", [])}
    share = (checks.get("subgoal_progress", {}).get("figures") or {}).get("final_share")
    end = checks.get("where_episodes_end", {})
    progress = (end.get("figures") or {}).get("progress_median")
    if share is None or progress is None:
        return None
    moved_on = end.get("ok") is False and curriculum_moved_on(share, progress)
    return {"record": record, "subgoal_share": round(float(share), 3), "progress_median": round(float(progress), 3),
            "episodes_flagged": end.get("ok") is False, "curriculum_moved_on": moved_on}


def main(argv: list[str] | None = None) -> dict[str, object]:
    """Reads each record; prints the table (stderr) and the JSON line; returns what the JSON line holds."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("records", nargs="+", help="record directories (docs/runs/<group>/<cell>)")
    args = parser.parse_args(argv)
    rows = [row for row in map(read_record, args.records) if row is not None]
    print("| record | last subgoal | episodes end (median) | moved on without the policy |", file=sys.stderr)
    print("|---|---|---|---|", file=sys.stderr)
    for row in rows:
        print(f"| {row['record']} | {row['subgoal_share']:.2f} | {row['progress_median']:.2f} | "
              f"{'yes' if row['curriculum_moved_on'] else '-'} |", file=sys.stderr)
    result = {"records": len(rows), "moved_on": [r["record"] for r in rows if r["curriculum_moved_on"]],
              "rows": rows}
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
