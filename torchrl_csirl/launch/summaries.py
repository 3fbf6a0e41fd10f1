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

__all__ = ["find_summaries", "mean_std", "regularized_incomplete_beta", "t_test_p_value", "welch_test"]


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


#: the level of :func:`welch_test`'s ``beyond_noise``: two-sided 5 %
SIGNIFICANCE = 0.05


def _beta_continued_fraction(a: float, b: float, x: float, iterations: int = 300, eps: float = 1e-15) -> float:
    """The continued fraction of the regularized incomplete beta function (modified Lentz's method)."""
    tiny = 1e-300

    def guarded(value: float) -> float:
        return value if abs(value) > tiny else tiny

    c, d = 1.0, 1.0 / guarded(1.0 - (a + b) * x / (a + 1.0))
    h = d
    for m in range(1, iterations + 1):
        even = m * (b - m) * x / ((a + 2 * m - 1.0) * (a + 2 * m))
        d, c = 1.0 / guarded(1.0 + even * d), guarded(1.0 + even / c)
        h *= d * c
        odd = -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1.0))
        d, c = 1.0 / guarded(1.0 + odd * d), guarded(1.0 + odd / c)
        h *= d * c
        if abs(d * c - 1.0) < eps:
            break
    return h


def regularized_incomplete_beta(x: float, a: float, b: float) -> float:
    """``I_x(a, b)``, the regularized incomplete beta function, for ``0 <= x <= 1`` and ``a, b > 0``.

    Examples:
        >>> round(regularized_incomplete_beta(0.5, 2.0, 2.0), 12)
        0.5
        >>> round(regularized_incomplete_beta(0.3, 1.0, 1.0), 12)  # the uniform distribution's CDF
        0.3
    """
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    log_front = math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x)
    if x < (a + 1.0) / (a + b + 2.0):
        return math.exp(log_front) * _beta_continued_fraction(a, b, x) / a
    return 1.0 - math.exp(log_front) * _beta_continued_fraction(b, a, 1.0 - x) / b


def t_test_p_value(t: float, dof: float) -> float:
    """Two-sided p-value of Student's t statistic ``t`` at ``dof`` degrees of freedom, fractional ones
    included (Welch-Satterthwaite's): ``P(|T| >= |t|) = I_{dof / (dof + t^2)}(dof / 2, 1 / 2)``.

    Examples:
        >>> round(t_test_p_value(2.776445, 4), 4)  # the 5 % critical value at 4 degrees of freedom
        0.05
        >>> round(t_test_p_value(-4.05, 2.76), 3)
        0.032
    """
    if math.isinf(t):
        return 0.0
    return regularized_incomplete_beta(dof / (dof + t * t), dof / 2.0, 0.5)


def welch_test(a: list[float], b: list[float]) -> dict[str, float | bool] | None:
    """Welch's t-test of ``mean(a) - mean(b)`` over seeds: ``difference``, ``t``, ``dof`` (Welch-Satterthwaite's,
    fractional), the two-sided ``p`` of Student's t at those degrees of freedom, and ``beyond_noise``
    (``p < 0.05``); ``None`` with fewer than two values on a side.

    Examples:
        >>> r = welch_test([0.95, 0.96, 0.97], [0.90, 0.91, 0.92])
        >>> round(r["difference"], 3), round(r["t"], 1), round(r["p"], 4), r["beyond_noise"]
        (0.05, 6.1, 0.0036, True)
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
                "p": 0.0 if difference else 1.0, "beyond_noise": difference != 0}
    t = difference / math.sqrt(va + vb)
    dof = (va + vb) ** 2 / (va**2 / (len(a) - 1) + vb**2 / (len(b) - 1))
    p = t_test_p_value(t, dof)
    return {"difference": difference, "t": t, "dof": dof, "p": p, "beyond_noise": p < SIGNIFICANCE}
