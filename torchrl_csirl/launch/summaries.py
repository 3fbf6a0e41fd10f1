"""Run summaries across seeds: find a sweep's ``summary.json`` files, their mean / std, and
Welch's t-test between two methods. Shared by ``recipes/benchmark.py`` (its report) and
``tools/summarize_runs.py``.

Examples:
    >>> mean_std([0.8, 1.0])["mean"]
    0.9
"""
from __future__ import annotations

import math
import os

__all__ = ["find_summaries", "mean_std", "welch_test"]


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
