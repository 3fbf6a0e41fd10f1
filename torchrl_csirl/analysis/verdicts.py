"""One rule for the pages' verdict words: two seed sets -> Welch's t-test, Holm's correction across the
comparisons of one study section, and the smallest difference the test could have detected.

The rule: a difference is **"beyond seed noise"** when its Holm-adjusted p is below
:data:`ALPHA` (two-sided 5 %); otherwise it is **"no difference detected"**, printed with the *minimum
detectable difference* at that number of seeds and those spreads, so that a reader sees how large a
difference the test could have missed. Nothing else ("level", "no effect", "fixed") is a verdict.

Welch's test: ``t = (mean(a) - mean(b)) / SE`` with ``SE = sqrt(s_a^2 / n_a + s_b^2 / n_b)`` (sample standard
deviations), Student's t at the Welch-Satterthwaite degrees of freedom
``nu = SE^4 / ((s_a^2 / n_a)^2 / (n_a - 1) + (s_b^2 / n_b)^2 / (n_b - 1))`` (fractional), two-sided p.

Holm's step-down correction of ``m`` p-values: sorted ascending ``p_(1) <= ... <= p_(m)``, the adjusted
``p~_(i) = max_{j <= i} min(1, (m - j + 1) p_(j))``; a test with fewer known p-values than comparisons is
given Holm's first step, Bonferroni's ``min(1, m p)``, the bound Holm never exceeds.

The minimum detectable difference at two-sided level ``alpha`` and power ``1 - beta`` (:data:`POWER`, 0.8):
``MDD = (t_{1 - alpha/2, nu} + t_{1 - beta, nu}) SE``, the usual approximation of the noncentral t's power by
two central t quantiles at Welch's degrees of freedom (with the normal quantiles, 1.96 + 0.84, for large n).
A true difference of that size is found beyond noise by 80 % of such experiments. In a section of ``m`` comparisons
``alpha`` is ``ALPHA / m``, the level of Holm's strictest step (Bonferroni's): a difference detectable there passes
Holm's correction whatever the other p-values. (``t_{1 - alpha/2, nu} SE`` alone, the difference that would just
reach p < alpha, is found half of the time.) With 3 seeds a side, note too that an exact permutation test cannot go
below p = 0.10 (:func:`permutation_p_floor`): complete separation of the two sets is 2 arrangements of 20.

Examples:
    >>> c = compare_seeds([0.95, 0.96, 0.97], [0.90, 0.91, 0.92])
    >>> round(c.difference, 3), round(c.t, 2), round(c.p, 4), c.verdict
    (0.05, 6.12, 0.0036, 'beyond seed noise')
    >>> c = compare_seeds([1.0, 0.97, 0.88], [1.0, 1.0, 1.0])
    >>> c.verdict, round(c.detectable, 2)
    ('no difference detected', 0.19)
    >>> describe(c)
    '-0.050 (t -1.39, p 0.3): no difference detected (detectable 0.193)'
    >>> seeds_needed(0.05, 0.05, 0.05)  # seeds a side to see a difference of one seed's spread
    17
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

from torchrl_csirl.analysis.summaries import mean_std

__all__ = [
    "ALPHA",
    "BEYOND_NOISE",
    "NO_DIFFERENCE",
    "POWER",
    "SeedComparison",
    "compare_family",
    "compare_seeds",
    "describe",
    "detectable_difference",
    "holm",
    "permutation_p_floor",
    "regularized_incomplete_beta",
    "seeds_needed",
    "t_quantile",
    "t_test_p_value",
]

#: two-sided level of the rule, after Holm's correction
ALPHA = 0.05
#: the power the minimum detectable difference is stated at
POWER = 0.8
#: the verdict words, the only two
BEYOND_NOISE = "beyond seed noise"
NO_DIFFERENCE = "no difference detected"


# ---------------------------------------------------------------------------------------- Student's t distribution
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


def t_quantile(upper: float, dof: float) -> float:
    """The ``t`` with ``P(T > t) = upper`` at ``dof`` degrees of freedom (fractional ones included), by bisection
    on :func:`t_test_p_value`.

    Examples:
        >>> round(t_quantile(0.025, 4), 4), round(t_quantile(0.2, 2), 4), round(t_quantile(0.8, 2), 4)
        (2.7764, 1.0607, -1.0607)
    """
    if not 0.0 < upper < 1.0:
        raise ValueError(f"upper must lie in (0, 1), got {upper}.")
    if upper > 0.5:
        return -t_quantile(1.0 - upper, dof)
    if upper == 0.5:
        return 0.0
    low, high = 0.0, 1.0
    while t_test_p_value(high, dof) > 2 * upper:  # P(|T| >= t) = 2 P(T > t) for t > 0
        low, high = high, 2 * high
    for _ in range(200):
        middle = (low + high) / 2
        if t_test_p_value(middle, dof) > 2 * upper:
            low = middle
        else:
            high = middle
        if high - low <= 1e-12 * high:
            break
    return (low + high) / 2


# ---------------------------------------------------------------------------------------- power and corrections
def _welch_parts(sd_a: float, n_a: int, sd_b: float, n_b: int) -> tuple[float, float]:
    """``(SE, nu)``: the standard error of the difference of two means and Welch-Satterthwaite's degrees of freedom
    (``n_a + n_b - 2`` when both spreads are 0)."""
    va, vb = sd_a**2 / n_a, sd_b**2 / n_b
    if va + vb == 0:
        return 0.0, float(n_a + n_b - 2)
    return math.sqrt(va + vb), (va + vb) ** 2 / (va**2 / (n_a - 1) + vb**2 / (n_b - 1))


def detectable_difference(sd_a: float, n_a: int, sd_b: float, n_b: int, alpha: float = ALPHA,
                          power: float = POWER) -> float:
    """The smallest true difference of means that Welch's two-sided test at level ``alpha`` detects with probability
    ``power``, for samples of ``n_a`` and ``n_b`` seeds with standard deviations ``sd_a`` and ``sd_b``:
    ``(t_{1 - alpha/2, nu} + t_{power, nu}) SE`` (module docstring).

    Examples:
        >>> round(detectable_difference(0.08, 3, 0.0, 3), 3)  # CSIRL against BC on the U-maze: 0.95 ± 0.08, 1.00 ± 0
        0.248
        >>> round(detectable_difference(0.08, 3, 0.0, 3, power=0.5), 3)  # the difference that just reaches p 0.05
        0.199
    """
    se, dof = _welch_parts(sd_a, n_a, sd_b, n_b)
    if se == 0:
        return 0.0
    return (t_quantile(alpha / 2, dof) + t_quantile(1.0 - power, dof)) * se


def seeds_needed(sd_a: float, sd_b: float, delta: float, alpha: float = ALPHA, power: float = POWER,
                 at_most: int = 10_000) -> int:
    """Seeds per side (the same on both) for Welch's test to detect a true difference ``delta`` at level ``alpha``
    with probability ``power``, given the spreads ``sd_a`` and ``sd_b`` of one seed's score on each side: the
    smallest ``n >= 2`` whose :func:`detectable_difference` is at most ``delta``.

    Raises:
        ValueError: ``delta`` not positive, or more than ``at_most`` seeds needed.

    Examples:
        >>> seeds_needed(0.08, 0.0, 0.05)  # the U-maze's spreads, to see 0.05 of the expert
        23
        >>> seeds_needed(0.0, 0.0, 0.05)  # no spread: two seeds a side are enough
        2
    """
    if not delta > 0:
        raise ValueError(f"delta must be > 0, got {delta}.")
    for n in range(2, at_most + 1):
        if detectable_difference(sd_a, n, sd_b, n, alpha, power) <= delta:
            return n
    raise ValueError(f"more than {at_most} seeds a side needed to detect {delta} with spreads {sd_a} and {sd_b}.")


def holm(p_values: Sequence[float]) -> list[float]:
    """Holm's step-down adjusted p-values, in the order given (module docstring).

    Examples:
        >>> [round(p, 3) for p in holm([0.01, 0.04, 0.03, 0.005])]
        [0.03, 0.06, 0.06, 0.02]
    """
    m = len(p_values)
    adjusted = [0.0] * m
    running = 0.0
    for rank, index in enumerate(sorted(range(m), key=lambda i: p_values[i])):
        running = max(running, min(1.0, (m - rank) * p_values[index]))
        adjusted[index] = running
    return adjusted


def permutation_p_floor(n_a: int, n_b: int) -> float:
    """The smallest two-sided p an exact permutation test of two samples of ``n_a`` and ``n_b`` can give: complete
    separation, 2 of the ``C(n_a + n_b, n_a)`` arrangements.

    Examples:
        >>> permutation_p_floor(3, 3), permutation_p_floor(5, 5)
        (0.1, 0.007936507936507936)
    """
    return min(1.0, 2.0 / math.comb(n_a + n_b, n_a))


# ---------------------------------------------------------------------------------------- the comparison
@dataclass(frozen=True)
class SeedComparison:
    """Welch's test of ``mean(a) - mean(b)`` over seeds, with its verdict under the rule.

    Attributes:
        difference: ``mean(a) - mean(b)``.
        t: Welch's t (``±inf`` for a difference with no spread on either side).
        dof: Welch-Satterthwaite's degrees of freedom, fractional.
        p: the two-sided p of Student's t at ``dof``.
        p_holm: ``p`` after Holm's correction across the section's ``comparisons``.
        comparisons: how many comparisons the section holds (1: none to correct for).
        detectable: the minimum detectable difference at ``n`` and these spreads (:func:`detectable_difference`), at
            the level of the correction's strictest step, ``ALPHA / comparisons``.
        n: seeds on each side.
    """

    difference: float
    t: float
    dof: float
    p: float
    p_holm: float
    comparisons: int
    detectable: float
    n: tuple[int, int]

    @property
    def beyond_noise(self) -> bool:
        """Whether the Holm-adjusted p is below :data:`ALPHA`."""
        return self.p_holm < ALPHA

    @property
    def verdict(self) -> str:
        """:data:`BEYOND_NOISE` or :data:`NO_DIFFERENCE`."""
        return BEYOND_NOISE if self.beyond_noise else NO_DIFFERENCE

    @property
    def permutation_floor(self) -> float:
        """The smallest p an exact permutation test could give at these ``n`` (0.10 with 3 seeds a side)."""
        return permutation_p_floor(*self.n)

    def as_dict(self) -> dict[str, float | int | bool | str | list[int]]:
        """The fields, the verdict and ``beyond_noise``, for a JSON line."""
        return {"difference": self.difference, "t": self.t, "dof": self.dof, "p": self.p, "p_holm": self.p_holm,
                "comparisons": self.comparisons, "detectable": self.detectable, "n": list(self.n),
                "beyond_noise": self.beyond_noise, "verdict": self.verdict}


def _welch(a: Sequence[float], b: Sequence[float]) -> tuple[float, float, float, float]:
    """``(difference, t, dof, p)`` of Welch's test of ``mean(a) - mean(b)``."""
    ma, mb = mean_std(list(a)), mean_std(list(b))
    difference = ma["mean"] - mb["mean"]
    se, dof = _welch_parts(ma["std"], len(a), mb["std"], len(b))
    if se == 0:
        return difference, math.copysign(math.inf, difference) if difference else 0.0, dof, 0.0 if difference else 1.0
    t = difference / se
    return difference, t, dof, t_test_p_value(t, dof)


def compare_seeds(a: Sequence[float], b: Sequence[float], comparisons: int = 1,
                  section_p_values: Sequence[float] | None = None) -> SeedComparison | None:
    """Welch's test of ``mean(a) - mean(b)`` with its verdict; None with fewer than two seeds on a side.

    Args:
        a, b: one score per seed on each side.
        comparisons: the number of comparisons in the study section (Holm's ``m``); without
            ``section_p_values`` the adjusted p is Holm's first step, ``min(1, m p)``.
        section_p_values: the p-values of the section's *other* comparisons: the adjusted p is then Holm's exactly,
            over ``[p, *section_p_values]`` (``comparisons`` is their number).

    Examples:
        >>> c = compare_seeds([0.95, 0.96, 0.97], [0.90, 0.91, 0.92], comparisons=12)
        >>> round(c.p_holm, 3), c.verdict
        (0.043, 'beyond seed noise')
        >>> compare_seeds([0.95, 0.96, 0.97], [0.90, 0.91, 0.92], section_p_values=[0.001, 0.002]).p_holm > 0.0036
        True
        >>> compare_seeds([0.9], [0.8, 0.7]) is None
        True
    """
    if len(a) < 2 or len(b) < 2:
        return None
    difference, t, dof, p = _welch(a, b)
    if section_p_values is not None:
        comparisons = 1 + len(section_p_values)
        p_holm = holm([p, *section_p_values])[0]
    else:
        if comparisons < 1:
            raise ValueError(f"comparisons must be >= 1, got {comparisons}.")
        p_holm = min(1.0, comparisons * p)
    stats_a, stats_b = mean_std(list(a)), mean_std(list(b))
    detectable = detectable_difference(stats_a["std"], len(a), stats_b["std"], len(b), alpha=ALPHA / comparisons)
    return SeedComparison(difference, t, dof, p, p_holm, comparisons, detectable, (len(a), len(b)))


def compare_family(pairs: Sequence[tuple[Sequence[float], Sequence[float]]]) -> list[SeedComparison | None]:
    """:func:`compare_seeds` of every ``(a, b)`` pair of one study section, Holm's correction across those that can
    be tested (a pair with fewer than two seeds on a side is None and no comparison).

    Examples:
        >>> family = compare_family([([0.95, 0.96, 0.97], [0.90, 0.91, 0.92]), ([0.9, 0.8, 0.95], [0.85, 0.9, 0.8]),
        ...                          ([0.5], [0.4, 0.6])])
        >>> [None if c is None else (c.comparisons, round(c.p_holm, 4), c.verdict) for c in family]
        [(2, 0.0072, 'beyond seed noise'), (2, 0.5666, 'no difference detected'), None]
    """
    testable = sum(len(a) > 1 and len(b) > 1 for a, b in pairs)
    tested = [compare_seeds(a, b, comparisons=max(testable, 1)) for a, b in pairs]
    adjusted = iter(holm([c.p for c in tested if c is not None]))
    return [None if c is None else replace(c, p_holm=next(adjusted)) for c in tested]


def describe(comparison: SeedComparison, fmt: str = "+.3f") -> str:
    """The comparison in the pages' words: ``difference (t, p[, Holm's p]): verdict``, with the detectable difference
    beside "no difference detected" (``fmt`` formats both).

    Examples:
        >>> describe(compare_seeds([0.95, 0.96, 0.97], [0.90, 0.91, 0.92], comparisons=3))
        '+0.050 (t 6.12, p 0.0036, Holm 0.011 of 3): beyond seed noise'
    """
    p = f"t {comparison.t:.2f}, p {_p(comparison.p)}"
    if comparison.comparisons > 1:
        p += f", Holm {_p(comparison.p_holm)} of {comparison.comparisons}"
    text = f"{comparison.difference:{fmt}} ({p}): {comparison.verdict}"
    if not comparison.beyond_noise:
        text += f" (detectable {comparison.detectable:{fmt.lstrip('+')}})"
    return text


def _p(p: float) -> str:
    """A p-value to two significant figures (``< 0.001`` below that)."""
    return "< 0.001" if p < 0.001 else f"{p:.2g}"
