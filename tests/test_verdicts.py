"""torchrl_csirl.analysis.verdicts: the one rule for verdict words, against values computed once independently.

SciPy is not a dependency; the reference values below were computed once with mpmath at 30 digits (the t
distribution's CDF as the regularized incomplete beta function, quantiles by root finding), the values
``scipy.stats.ttest_ind(a, b, equal_var=False)`` and ``scipy.stats.t.ppf`` give.
"""
from __future__ import annotations

import math

import pytest

from torchrl_csirl.analysis.verdicts import (
    BEYOND_NOISE,
    NO_DIFFERENCE,
    compare_family,
    compare_seeds,
    describe,
    detectable_difference,
    holm,
    permutation_p_floor,
    seeds_needed,
    t_quantile,
    t_test_p_value,
)

#: (upper tail, degrees of freedom) -> t
QUANTILES = {(0.025, 2): 4.302652729749464, (0.2, 2): 1.060660171779821, (0.025, 4): 2.776445105197794,
             (0.2, 4): 0.940964577235181, (0.025, 2.5): 3.574654842003687, (0.025, 10): 2.228138851986275,
             (0.2, 10): 0.879057828550589, (0.025, 3.7): 2.867520707191189}
#: (a, b) -> Welch's t, degrees of freedom, two-sided p, and the minimum detectable difference (5 %, power 0.8)
WELCH = [
    (([0.95, 0.96, 0.97], [0.90, 0.91, 0.92]), (6.123724357, 4.0, 0.003602232609, 0.03035252296)),
    (([0.9, 0.8, 0.95], [0.85, 0.9, 0.8]), (0.632455532, 3.448275862, 0.5665671267, 0.206571186)),
    (([0.71, 0.55, 0.62, 0.80], [0.52, 0.49, 0.61]), (1.994108971, 4.822024472, 0.104813264, 0.2296088333)),
    (([1.0, 0.97, 0.88], [1.0, 1.0, 1.0]), (-1.386750491, 2.0, 0.299859958, 0.1933769967)),
]


@pytest.mark.parametrize(("upper", "dof"), list(QUANTILES))
def test_t_quantiles_are_the_tables(upper, dof):
    t = t_quantile(upper, dof)
    assert t == pytest.approx(QUANTILES[(upper, dof)], rel=1e-9)
    assert t_test_p_value(t, dof) == pytest.approx(2 * upper, rel=1e-9)
    assert t_quantile(1 - upper, dof) == pytest.approx(-t)


@pytest.mark.parametrize(("samples", "expected"), WELCH)
def test_welch_t_p_and_detectable_difference_are_the_reference_values(samples, expected):
    a, b = samples
    c = compare_seeds(a, b)
    t, dof, p, detectable = expected
    assert (c.t, c.dof, c.p, c.detectable) == pytest.approx((t, dof, p, detectable), rel=1e-8)
    assert c.difference == pytest.approx(sum(a) / len(a) - sum(b) / len(b))
    assert c.n == (len(a), len(b)) and c.comparisons == 1 and c.p_holm == c.p
    assert c.verdict == (BEYOND_NOISE if p < 0.05 else NO_DIFFERENCE)


def test_holm_on_a_known_list():
    assert holm([0.01, 0.04, 0.03, 0.005]) == pytest.approx([0.03, 0.06, 0.06, 0.02])
    assert holm([0.5, 0.6]) == [1.0, 1.0]  # capped at 1, monotone
    assert holm([0.02]) == [0.02] and holm([]) == []


def test_a_section_of_comparisons_corrects_each_verdict_and_its_detectable_difference():
    """p 0.0036 is beyond noise alone and among 2 tests (Holm 0.0072), not among 14 others of p 0.5 to 1 (Holm 0.054);
    the detectable difference grows with the section (its strictest level, 0.05 / m)."""
    strong = ([0.95, 0.96, 0.97], [0.90, 0.91, 0.92])
    weak = ([0.9, 0.8, 0.95], [0.85, 0.9, 0.8])
    pair = compare_family([strong, weak, ([0.5], [0.5, 0.6])])
    assert pair[2] is None and [c.comparisons for c in pair[:2]] == [2, 2]
    assert pair[0].p_holm == pytest.approx(2 * 0.003602232609) and pair[0].verdict == BEYOND_NOISE
    assert pair[1].p_holm == pytest.approx(0.5665671267 * 1) and pair[1].verdict == NO_DIFFERENCE
    section = compare_seeds(*strong, section_p_values=[0.5 + i / 30 for i in range(14)])
    assert section.comparisons == 15 and section.p_holm == pytest.approx(15 * 0.003602232609)
    assert section.verdict == NO_DIFFERENCE
    alone = compare_seeds(*strong)
    assert section.detectable == pytest.approx(detectable_difference(0.01, 3, 0.01, 3, alpha=0.05 / 15))
    assert section.detectable > alone.detectable
    assert compare_seeds(*strong, comparisons=12).p_holm == pytest.approx(12 * 0.003602232609)  # Holm's first step


def test_the_detectable_difference_and_the_seeds_it_takes():
    # the U-maze: CSIRL 0.95 ± 0.08 against BC's 1.00 ± 0.00, 3 seeds: the difference that just reaches
    # p < 0.05 is t_{0.975, 2} SE = 0.199; at power 0.8 (t_{0.975, 2} + t_{0.8, 2}) SE
    se = 0.08 / math.sqrt(3)
    assert detectable_difference(0.08, 3, 0.0, 3, power=0.5) == pytest.approx(4.302652729749464 * se, rel=1e-9)
    assert detectable_difference(0.08, 3, 0.0, 3) == pytest.approx((4.302652729749464 + 1.060660171779821) * se, rel=1e-9)
    assert detectable_difference(0.0, 3, 0.0, 3) == 0.0
    for sd_a, sd_b, delta in ((0.08, 0.0, 0.05), (0.05, 0.03, 0.05), (0.2, 0.2, 0.1)):
        n = seeds_needed(sd_a, sd_b, delta)
        assert detectable_difference(sd_a, n, sd_b, n) <= delta < detectable_difference(sd_a, n - 1, sd_b, n - 1)
    # large n: the normal approximation 2 (z_{0.975} + z_{0.8})^2 sd^2 / delta^2 = 1569.8
    assert abs(seeds_needed(1.0, 1.0, 0.1) - 1570) <= 2
    assert seeds_needed(0.0, 0.0, 0.01) == 2
    with pytest.raises(ValueError, match="delta must be > 0"):
        seeds_needed(0.1, 0.1, 0.0)


def test_an_exact_permutation_test_of_three_seeds_a_side_cannot_go_below_p_0_10():
    assert permutation_p_floor(3, 3) == pytest.approx(0.10)
    assert compare_seeds([1.0, 1.1, 1.2], [0.0, 0.1, 0.2]).permutation_floor == pytest.approx(0.10)
    assert permutation_p_floor(5, 5) == pytest.approx(2 / 252)


def test_degenerate_sets_and_the_pages_words():
    assert compare_seeds([0.9], [0.8, 0.7]) is None
    same = compare_seeds([1.0, 1.0], [1.0, 1.0])
    assert (same.t, same.p, same.detectable, same.verdict) == (0.0, 1.0, 0.0, NO_DIFFERENCE)
    apart = compare_seeds([1.0, 1.0], [0.0, 0.0])
    assert math.isinf(apart.t) and apart.p == 0.0 and apart.verdict == BEYOND_NOISE
    assert describe(compare_seeds([1.0, 0.97, 0.88], [1.0, 1.0, 1.0])) == (
        "-0.050 (t -1.39, p 0.3): no difference detected (detectable 0.193)")
    assert compare_seeds([1.0, 0.97, 0.88], [1.0, 1.0, 1.0]).as_dict()["verdict"] == NO_DIFFERENCE
