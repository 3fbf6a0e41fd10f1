"""A sweep's finished runs and the table's rows: each run's ``summary.json`` read with its row's method,
grouped by (method, scenario) into mean ± std over seeds, set against ``csirl`` (Welch's test and the verdict
rule of :mod:`torchrl_csirl.analysis.verdicts`, Holm's correction across one table's comparisons) and the
paper's value (:mod:`torchrl_csirl.sweep.published`).

The rows are plain dicts, the CSV's lines; :mod:`torchrl_csirl.sweep.report` writes them as Markdown.

Examples:
    >>> rows = table_rows([{"method": "csirl", "scenario": "merge", "seed": s, "run_dir": "",
    ...                     "normalized_accomplish_rate": r} for s, r in ((0, 0.8), (1, 0.9))])
    >>> [(r["method"], r["runs"], round(r["normalized_accomplish_rate_mean"], 2), r["paper"]) for r in rows]
    [('csirl', 2, 0.85, 0.92)]
"""
from __future__ import annotations

import json
import os
from collections import defaultdict
from typing import Any

from torchrl_csirl.analysis.summaries import find_summaries, mean_std
from torchrl_csirl.analysis.verdicts import compare_family
from torchrl_csirl.sweep.plan import (
    ABLATIONS,
    LOCOMOTION_ORDER,
    METHOD_ORDER,
    REFERENCE_METHODS,
    SCENARIO_ORDER,
    TABLE_BUDGETS,
    known_methods,
    return_task_order,
    score_key,
)
from torchrl_csirl.sweep.published import PAPER_TABLE

__all__ = ["add_comparison_to_csirl", "add_normalized_returns", "best_evaluation", "cell_method", "comparison_table",
           "eval_curve", "off_budget", "read_runs", "table_rows"]


def cell_method(summary: dict[str, Any], run_dir: str) -> str:
    """The row of a run: the label its directory's name ``<scenario>-<label>-s<seed>`` gives when
    that label is a known method (the ablations' runs say ``csirl`` in their summary) or extends the
    summary's method (``antmaze-umaze-csirl-bc-path-s0``, a ``csirl`` run, gets a row of its own
    instead of joining CSIRL's), else the summary's own method.

    Examples:
        >>> cell_method({"scenario": "merge", "seed": 0, "method": "csirl"}, "runs/merge-csirl-nocur-s0")
        'csirl-nocur'
        >>> cell_method({"scenario": "merge", "seed": 0, "method": "csirl"}, "runs/merge-csirl-mine-s0")
        'csirl-mine'
        >>> cell_method({"scenario": "merge", "seed": 0, "method": "csirl-b"}, "runs/merge-b-s0")
        'csirl-b'
    """
    method = summary["method"]
    prefix, suffix = f"{summary.get('scenario')}-", f"-s{summary.get('seed')}"
    name = os.path.basename(os.path.normpath(run_dir))
    if not (name.startswith(prefix) and name.endswith(suffix) and len(name) > len(prefix) + len(suffix)):
        return method
    label = name[len(prefix):-len(suffix)]
    return label if label in known_methods() or label.startswith(f"{method}-") else method


def read_runs(paths: list[str]) -> list[dict[str, Any]]:
    """The summaries of the finished runs under ``paths``, each with its run directory and method."""
    runs = []
    for path in find_summaries(paths):
        with open(path) as f:
            summary = json.load(f)
        summary["run_dir"] = os.path.dirname(path)
        summary["method"] = cell_method(summary, summary["run_dir"])
        runs.append(summary)
    return runs


def add_normalized_returns(runs: list[dict[str, Any]]) -> None:
    """Each locomotion run's ``normalized_return``: ``R / R_expert``, the reference the mean test return of the
    ``expert`` row on the same task (the same test episodes); none without that row. The convention of the
    published table beside ours (IQ-Learn's Table 3 gives raw returns and its expert's: R / R_expert).

    Examples:
        >>> runs = [{"method": "expert", "scenario": "hopper", "return": 3500.0},
        ...         {"method": "csirl", "scenario": "hopper", "return": 1750.0}]
        >>> add_normalized_returns(runs)
        >>> [r["normalized_return"] for r in runs]
        [1.0, 0.5]
    """
    for task in LOCOMOTION_ORDER:
        values = [float(r["return"]) for r in runs if r["scenario"] == task and r["method"] == "expert"]
        expert = sum(values) / len(values) if values else None
        expert = expert if expert is not None and expert > 0 else None  # no reference to divide by
        for run in (r for r in runs if r["scenario"] == task):
            ok = expert is not None and run.get("return") is not None
            run["normalized_return"] = float(run["return"]) / expert if ok else None
            best = best_evaluation(run["run_dir"]) if run.get("run_dir") else None
            run["best_eval_return"] = best
            run["normalized_best_eval_return"] = None if best is None or expert is None else best / expert


def best_evaluation(run_dir: str, key: str = "eval_env_return") -> float | None:
    """The highest periodic evaluation of a run (``key`` of its ``metrics.jsonl`` rows; none without any): the
    figure the published locomotion rows report (IQ-Learn's code keeps the best evaluation, SQIL's paper the best
    10-episode mean). A maximum over noisy evaluations sits above what one evaluation would expect, and the
    validation episodes that choose it score it too: an optimistic figure, beside the final policy's test return.

    Examples:
        >>> import tempfile
        >>> run_dir = tempfile.mkdtemp()
        >>> with open(os.path.join(run_dir, "metrics.jsonl"), "w") as f:
        ...     _ = f.write('{"frames": 2, "eval_env_return": 5.0}\\n{"frames": 4, "loss": 1.0}\\n'
        ...                 '{"frames": 6, "eval_env_return": 3.0}\\n')
        >>> best_evaluation(run_dir), best_evaluation(tempfile.mkdtemp())
        (5.0, None)
    """
    values = eval_curve(run_dir, key)[1]
    return max(values) if values else None


def table_rows(runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per (method, scenario): expert-normalised and raw accomplish rate over seeds (on the locomotion
    tasks the expert-normalised return, :func:`add_normalized_returns`), cost, the paper's value."""
    add_normalized_returns(runs)
    groups: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for run in runs:
        groups[(run["method"], run["scenario"])].append(run)
    rank = {m: i for i, m in enumerate((*METHOD_ORDER, *ABLATIONS))}
    column = {s: i for i, s in enumerate((*SCENARIO_ORDER, *return_task_order([r["scenario"] for r in runs])))}
    rows = []
    for (method, scenario), group in sorted(groups.items(), key=lambda kv: (rank.get(kv[0][0], 99), kv[0][0],
                                                                              column.get(kv[0][1], 99), kv[0][1])):
        row: dict[str, Any] = {"method": method, "scenario": scenario, "seeds": " ".join(
            str(s) for s in sorted(int(r["seed"]) for r in group)), "runs": len(group),
            "frames": " ".join(str(f) for f in sorted({int(r.get("frames") or 0) for r in group}))}
        for field in ("normalized_accomplish_rate", "accomplish_rate", "return", "normalized_return",
                      "normalized_best_eval_return", "best_eval_return", "success_rate", "crash_rate", "total_wall_s",
                      "updates_per_s"):
            values = [float(r[field]) for r in group if r.get(field) is not None]
            stats = mean_std(values) if values else {"mean": None, "std": None}
            row[f"{field}_mean"], row[f"{field}_std"] = stats["mean"], stats["std"]
        row["paper"] = PAPER_TABLE.get(method, {}).get(scenario)
        rows.append(row)
    add_comparison_to_csirl(rows, groups)
    return rows


def comparison_table(scenario: str) -> str:
    """The table a scenario's comparisons are printed in, one study section for Holm's correction: ``driving``
    (the paper's scenes), ``locomotion`` or ``return`` (every other task's, robotics and goal-conditioned).

    Examples:
        >>> comparison_table("merge"), comparison_table("hopper"), comparison_table("PointMaze_UMaze-v3")
        ('driving', 'locomotion', 'return')
    """
    if scenario in SCENARIO_ORDER:
        return "driving"
    return "locomotion" if scenario in LOCOMOTION_ORDER else "return"


def add_comparison_to_csirl(rows: list[dict[str, Any]], groups: dict[tuple[str, str], list[dict]]) -> None:
    """Each row's difference from ``csirl`` on its scenario (in its :func:`score_key`: expert-normalised on the
    driving scenarios, the return on the robotics tasks), with Welch's test over seeds and the verdict rule
    (:func:`~torchrl_csirl.analysis.verdicts.compare_family`: Holm's correction across the comparisons of one
    :func:`comparison_table`): ``vs_csirl`` (the difference), ``vs_csirl_t``, ``vs_csirl_p``, ``vs_csirl_p_holm``,
    ``vs_csirl_comparisons``, ``vs_csirl_detectable`` (the minimum detectable difference), ``vs_csirl_beyond_noise``
    and ``vs_csirl_verdict``; None without a comparison (``csirl`` itself, the reference rows ``expert`` and
    ``random``, which no page compares, fewer than two seeds on a side)."""
    def values(method: str, scenario: str) -> list[float]:
        key = score_key(scenario)
        return [float(r[key]) for r in groups.get((method, scenario), []) if r.get(key) is not None]

    sections: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for row in rows:
        if row["method"] != "csirl" and row["method"] not in REFERENCE_METHODS:
            sections[comparison_table(row["scenario"])].append(row)
    for row in rows:
        for field in _COMPARISON_FIELDS:
            row[f"vs_csirl{field}"] = None
    for section in sections.values():
        family = compare_family([(values(r["method"], r["scenario"]), values("csirl", r["scenario"])) for r in section])
        for row, test in zip(section, family):
            if test is not None:
                row.update({"vs_csirl": test.difference, "vs_csirl_t": test.t, "vs_csirl_p": test.p,
                            "vs_csirl_p_holm": test.p_holm, "vs_csirl_comparisons": test.comparisons,
                            "vs_csirl_detectable": test.detectable, "vs_csirl_beyond_noise": test.beyond_noise,
                            "vs_csirl_verdict": test.verdict})


#: the comparison's fields of a table row, after ``vs_csirl``
_COMPARISON_FIELDS = ("", "_t", "_p", "_p_holm", "_comparisons", "_detectable", "_beyond_noise", "_verdict")


def off_budget(row: dict[str, Any]) -> bool:
    """Whether a table row's training runs ran another budget than its scene's :data:`TABLE_BUDGETS` entry
    (beyond 1 %: a run ends on its last whole batch); reference rows (no training, 0 frames) never are.

    Examples:
        >>> off_budget({"scenario": "roundabout", "frames": "110000"}), off_budget({"scenario": "relocate", "frames": "60200"})
        (True, False)
        >>> off_budget({"scenario": "merge", "frames": "0"})
        False
    """
    budget = TABLE_BUDGETS.get(row["scenario"])
    frames = [int(f) for f in str(row.get("frames", "")).split() if int(f) > 0]
    return budget is not None and any(abs(f - budget) > budget / 100 for f in frames)


def eval_curve(run_dir: str, key: str = "eval_accomplish_rate") -> tuple[list[float], list[float]]:
    """(frames, ``key``) of a run's ``metrics.jsonl``, the evaluation accomplish rate by default (empty for a
    reference row)."""
    path = os.path.join(run_dir, "metrics.jsonl")
    frames, values = [], []
    if os.path.isfile(path):
        with open(path) as f:
            for line in f:
                row = json.loads(line) if line.strip() else {}
                if row.get(key) is not None:
                    frames.append(float(row["frames"]))
                    values.append(float(row[key]))
    return frames, values

