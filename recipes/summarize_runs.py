"""Aggregate finished runs of ``recipes/csirl_highway.py``: mean and std over seeds, per scenario.

Reads ``summary.json`` of every run directory given (or found under a folder), groups the runs by
(scenario, method, preset, variant) and prints a Markdown table (to stderr) and, last, one JSON
line with the per-group statistics. The *variant* lists the run's configuration values that differ
from its preset's defaults (read from the run's ``config.yaml``; seeds, logging, checkpointing and
thread counts do not count), e.g. ``replay_buffer.expert_fraction=0``.

Usage::

    python recipes/summarize_runs.py runs/                     # every run under runs/
    python recipes/summarize_runs.py runs/merge-s0 runs/merge-s1 runs/merge-s2

Examples:
    >>> from summarize_runs import summarize  # doctest: +SKIP
    >>> summarize([{"scenario": "merge", "method": "csirl", "preset": "default",
    ...             "accomplish_rate": 0.9, "seed": 0}])["merge/csirl/default"]["accomplish_rate"]["mean"]
    0.9
"""
from __future__ import annotations

import argparse
import functools
import json
import math
import os
import sys
from collections import defaultdict

from omegaconf import OmegaConf

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from common.config import flatten_config, format_override  # noqa: E402
from common.registry import load_config_for  # noqa: E402

#: configuration keys that do not change what a run learns (or are shown elsewhere in the key)
NOT_A_VARIANT = ("seed", "device", "preset", "env.scenario", "csirl.intrinsic", "collector.main_threads", "logger.", "checkpoint.")

#: summary fields reported as mean / std over seeds
FIELDS = (
    "accomplish_rate",
    "normalized_accomplish_rate",
    "success_rate",
    "crash_rate",
    "auc",
    "frames",
    "updates",
    "wall_s",
    "total_wall_s",
    "updates_per_s",
    "collect_fps",
)


def find_summaries(paths: list[str]) -> list[str]:
    """``summary.json`` files of the run directories given, or of those directly under a folder."""
    found = []
    for path in paths:
        if os.path.isfile(os.path.join(path, "summary.json")):
            found.append(os.path.join(path, "summary.json"))
        elif os.path.isdir(path):
            found.extend(
                os.path.join(path, name, "summary.json")
                for name in sorted(os.listdir(path))
                if os.path.isfile(os.path.join(path, name, "summary.json"))
            )
        else:
            raise FileNotFoundError(f"{path}: neither a run directory with summary.json nor a folder of runs")
    if not found:
        raise FileNotFoundError(f"no summary.json under {paths} (runs not finished?)")
    return found


@functools.lru_cache(maxsize=None)
def _preset_defaults(method: str, preset: str) -> dict[str, object]:
    return flatten_config(load_config_for(method)([f"preset={preset}"]))


def variant(run_dir: str, preset: str, method: str = "csirl") -> str:
    """``key=value`` of the run's configuration entries that differ from ``preset``'s defaults
    (those of the recipe that trains ``method``).

    Empty for a run of the preset as it is, or when the run directory has no ``config.yaml``.
    """
    path = os.path.join(run_dir, "config.yaml")
    if not os.path.isfile(path):
        return ""
    run = flatten_config(OmegaConf.load(path))
    default = _preset_defaults(method, preset)
    changed = [
        format_override(key, value)
        for key, value in sorted(run.items())
        if not key.startswith(NOT_A_VARIANT) and default.get(key, object()) != value
    ]
    return " ".join(changed)


def mean_std(values: list[float]) -> dict[str, float]:
    """Mean and sample standard deviation (0 for a single value)."""
    mean = sum(values) / len(values)
    var = sum((v - mean) ** 2 for v in values) / (len(values) - 1) if len(values) > 1 else 0.0
    return {"mean": mean, "std": math.sqrt(var)}


#: two-sided 5 % critical values of Student's t by degrees of freedom (more than 10: 2.2 and below)
_T_CRITICAL_5 = {1: 12.71, 2: 4.30, 3: 3.18, 4: 2.78, 5: 2.57, 6: 2.45, 7: 2.36, 8: 2.31, 9: 2.26, 10: 2.23}


def welch_test(a: list[float], b: list[float]) -> dict[str, float | bool] | None:
    """Welch's t-test of ``mean(a) - mean(b)`` over seeds: ``difference``, ``t``, ``dof`` and
    ``beyond_noise`` (two-sided, 5 %); ``None`` with fewer than two values on a side.

    Examples:
        >>> r = welch_test([0.95, 0.96, 0.97], [0.90, 0.91, 0.92])
        >>> round(r["difference"], 3), round(r["t"], 1), r["beyond_noise"]
        (0.05, 6.1, True)
        >>> welch_test([0.9, 0.8, 0.95], [0.85, 0.9, 0.8])["beyond_noise"]
        False
    """
    if len(a) < 2 or len(b) < 2:
        return None
    ma, mb = mean_std(a), mean_std(b)
    va, vb = ma["std"] ** 2 / len(a), mb["std"] ** 2 / len(b)
    difference = ma["mean"] - mb["mean"]
    if va + vb == 0:
        return {"difference": difference, "t": math.inf if difference else 0.0, "dof": float(len(a) + len(b) - 2),
                "beyond_noise": difference != 0}
    t = difference / math.sqrt(va + vb)
    dof = (va + vb) ** 2 / (va**2 / (len(a) - 1) + vb**2 / (len(b) - 1))
    critical = _T_CRITICAL_5.get(max(1, int(dof)), 2.2)
    return {"difference": difference, "t": t, "dof": dof, "beyond_noise": abs(t) > critical}


def summarize(summaries: list[dict]) -> dict[str, dict]:
    """Group run summaries by ``scenario/method/preset[ variant]``; mean/std of :data:`FIELDS` per group."""
    groups: dict[str, list[dict]] = defaultdict(list)
    for s in summaries:
        key = f"{s['scenario']}/{s['method']}/{s['preset']}"
        groups[f"{key} {s['variant']}" if s.get("variant") else key].append(s)
    out = {}
    for key, runs in sorted(groups.items()):
        stats: dict[str, object] = {"seeds": sorted(int(r["seed"]) for r in runs)}
        for field in FIELDS:
            values = [float(r[field]) for r in runs if r.get(field) is not None]
            if values:
                stats[field] = mean_std(values)
        out[key] = stats
    return out


def markdown_table(stats: dict[str, dict]) -> str:
    """One row per group: mean ± std of the main figures."""
    head = ("| scenario / method / preset | seeds | accomplish (raw) | expert-normalised | success | crash | AUC | frames "
            "| updates | wall [min] |")
    rows = [head, "|---" * (head.count("|") - 1) + "|"]

    def cell(s: dict, field: str, fmt: str = "{:.3f}", scale: float = 1.0) -> str:
        if field not in s:
            return "n/a"
        return f"{fmt.format(s[field]['mean'] * scale)} ± {fmt.format(s[field]['std'] * scale)}"

    for key, s in stats.items():
        rows.append(
            f"| {key} | {','.join(map(str, s['seeds']))} | {cell(s, 'accomplish_rate')} | "
            f"{cell(s, 'normalized_accomplish_rate')} | {cell(s, 'success_rate', '{:.2f}')} | "
            f"{cell(s, 'crash_rate', '{:.2f}')} | {cell(s, 'auc')} | "
            f"{cell(s, 'frames', '{:.0f}')} | {cell(s, 'updates', '{:.0f}')} | {cell(s, 'total_wall_s', '{:.1f}', 1 / 60)} |"
        )
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> dict[str, dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("paths", nargs="+", help="run directories, or folders holding run directories")
    args = parser.parse_args(argv)
    summaries = []
    for path in find_summaries(args.paths):
        with open(path) as f:
            summary = json.load(f)
        summary["variant"] = variant(os.path.dirname(path), summary.get("preset", "default"),
                                     summary.get("method", "csirl"))
        summaries.append(summary)
    stats = summarize(summaries)
    print(markdown_table(stats), file=sys.stderr)
    print(json.dumps(stats))
    return stats


if __name__ == "__main__":
    main()
