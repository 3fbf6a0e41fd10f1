"""Run summaries across seeds: find a sweep's ``summary.json`` files and their mean / std. Shared by
``recipes/benchmark.py`` (its report) and ``torchrl-csirl summarize``; the tests between two seed sets and their
verdict words are :mod:`torchrl_csirl.analysis.verdicts`'.

Examples:
    >>> mean_std([0.8, 1.0])["mean"]
    0.9
"""
from __future__ import annotations

import math
import os

__all__ = ["find_summaries", "mean_std"]


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


def mean_std(values: list[float]) -> dict[str, float]:
    """Mean and sample standard deviation (0 for a single value)."""
    mean = sum(values) / len(values)
    var = sum((v - mean) ** 2 for v in values) / (len(values) - 1) if len(values) > 1 else 0.0
    return {"mean": mean, "std": math.sqrt(var)}
