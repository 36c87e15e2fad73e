"""lerobot_omnid.measure.stats against published values (SciPy is not installed here, so the sources are
cited) and against the definitions."""

from __future__ import annotations

import math

import pytest

from lerobot_omnid.measure.stats import (
    Z_95,
    chi2_sf,
    equal_rates,
    fisher_exact,
    heterogeneity,
    mantel_haenszel,
    rate_difference,
    spearman,
    wilson_interval,
)


@pytest.mark.parametrize(
    ("successes", "n", "low", "high"),
    [
        # Newcombe 1998 (Stat. Med. 17: 857-872), Table I, method 3 (score interval without correction)
        (81, 263, 0.2553, 0.3662),
        (15, 148, 0.0624, 0.1605),
        (0, 20, 0.0, 0.1611),
        (1, 29, 0.0061, 0.1718),
        (7, 10, 0.3968, 0.8922),  # docs/results.md's 7/10: 39.7-89.2 %
        (0, 10, 0.0, 0.2775),  # docs/results.md's 0/10: 0-27.8 %
        (10, 10, 0.7225, 1.0),
    ],
)
def test_wilson_interval_known_values(successes, n, low, high):
    estimate = wilson_interval(successes, n)
    assert estimate.value == successes / n
    assert estimate.low == pytest.approx(low, abs=1e-4) and estimate.high == pytest.approx(high, abs=1e-4)


def test_wilson_interval_solves_the_score_equation():
    """Each end p of the interval satisfies |k/n - p| = z sqrt(p (1 - p) / n) (the definition)."""
    for successes, n in ((3, 17), (12, 40), (49, 50)):
        estimate = wilson_interval(successes, n)
        for p in (estimate.low, estimate.high):
            assert abs(successes / n - p) == pytest.approx(Z_95 * math.sqrt(p * (1 - p) / n), rel=1e-9)


@pytest.mark.parametrize(
    ("table", "p_value"),
    [
        (((3, 4), (1, 4)), 0.4857),  # Fisher's tea tasting [[3, 1], [1, 3]]: R's fisher.test(TeaTasting)
        (((12, 40), (0, 40)), 0.0001855),  # 12/40 vs 0/40: the p = 0.0002 of docs/results.md
        (((7, 10), (0, 10)), 0.003096),  # 7/10 vs 0/10 blind: 2 * comb(13, 3) / comb(20, 10), p = 0.003
        (((7, 10), (5, 10)), 0.6499),  # 70 % vs 50 % of 10 each: p = 0.65, far from any difference
        (((0, 5), (0, 5)), 1.0),
    ],
)
def test_fisher_exact_known_values(table, p_value):
    (k1, n1), (k2, n2) = table
    assert fisher_exact(k1, n1, k2, n2) == pytest.approx(p_value, rel=1e-3)
    assert fisher_exact(k2, n2, k1, n1) == pytest.approx(p_value, rel=1e-3)  # symmetric in the rows


def test_fisher_exact_matches_the_hypergeometric_definition():
    """p = sum of hypergeometric probabilities of the tables no more probable than the observed one."""
    k1, n1, k2, n2 = 4, 9, 8, 11
    column, total = k1 + k2, n1 + n2
    probabilities = {
        x: math.comb(column, x) * math.comb(total - column, n1 - x) / math.comb(total, n1)
        for x in range(max(0, n1 + column - total), min(n1, column) + 1)
    }
    assert sum(probabilities.values()) == pytest.approx(1.0)
    expected = sum(p for p in probabilities.values() if p <= probabilities[k1] * (1 + 1e-9))
    assert fisher_exact(k1, n1, k2, n2) == pytest.approx(expected, rel=1e-12)


def test_rate_difference_newcombe_examples():
    """Newcombe 1998 (Stat. Med. 17: 873-890), Table II, method 10 (hybrid score, no correction)."""
    for (k1, n1, k2, n2), (low, high) in {
        (56, 70, 48, 80): (0.0524, 0.3339),
        (9, 10, 3, 10): (0.1705, 0.8090),
        (5, 56, 0, 29): (-0.0381, 0.1926),
        (0, 10, 0, 20): (-0.1611, 0.2775),
        (10, 10, 0, 20): (0.6791, 1.0),
    }.items():
        estimate = rate_difference(k1, n1, k2, n2)
        assert estimate.value == pytest.approx(k1 / n1 - k2 / n2)
        assert estimate.low == pytest.approx(low, abs=1e-4) and estimate.high == pytest.approx(high, abs=1e-4)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: wilson_interval(11, 10), r"successes: expected an int in \[0, n=10\], got 11"),
        (lambda: wilson_interval(0, 0), "n: expected at least 1 episode, got 0"),
        (lambda: wilson_interval(2.0, 10), "successes: expected an int, got 2.0"),
        (lambda: fisher_exact(1, 4, -1, 4), r"successes_2: expected an int in \[0, n_2=4\], got -1"),
        (lambda: rate_difference(1, 4, 1, 0), "n_2: expected at least 1 episode, got 0"),
    ],
)
def test_bad_counts_are_named(call, message):
    with pytest.raises((ValueError, TypeError), match=message):
        call()


def test_chi2_sf_closed_forms():
    """Tabulated quantiles (upper tail 0.05 and 0.01) and the tail at 0."""
    for x, df, tail in ((3.841459, 1, 0.05), (5.991465, 2, 0.05), (11.070498, 5, 0.05), (16.811894, 6, 0.01)):
        assert chi2_sf(x, df) == pytest.approx(tail, rel=1e-5)
    assert chi2_sf(0.0, 3) == 1.0
    with pytest.raises(ValueError, match="df: expected a positive int, got 0"):
        chi2_sf(1.0, 0)


def test_mantel_haenszel_matches_statsmodels():
    """p-values of statsmodels' ``StratifiedTable.test_null_odds(correction=True)`` on the same tables; a
    stratum where nobody succeeds adds nothing; no informative stratum gives p = 1."""
    assert mantel_haenszel([(10, 15, 5, 15), (12, 15, 6, 15)]) == pytest.approx(0.0103365021, rel=1e-8)
    with_empty = [(3, 15, 1, 15), (0, 15, 0, 15), (9, 15, 2, 15)]
    assert mantel_haenszel(with_empty) == pytest.approx(0.0148876709, rel=1e-8)
    assert mantel_haenszel([(0, 15, 0, 15), (15, 15, 15, 15)]) == 1.0


def test_heterogeneity_separates_a_steady_difference_from_a_reversed_one():
    steady = heterogeneity([(10, 15, 5, 15), (10, 15, 5, 15), (11, 15, 6, 15)])
    assert steady.df == 2 and steady.q < 0.1 and steady.p > 0.9 and steady.i2 == 0.0
    reversed_ = heterogeneity([(10, 15, 5, 15), (12, 15, 6, 15), (0, 15, 14, 15)])
    assert reversed_.p < 1e-6 and reversed_.i2 > 0.9
    with pytest.raises(ValueError, match="strata: expected at least 2 to compare, got 1"):
        heterogeneity([(1, 2, 1, 2)])


def test_equal_rates_statistic_and_permutation_p():
    """Pearson's statistic by hand; draws that all succeed alike are not different (p = 1); 10/10 against
    0/10 is (the exact two-sided Fisher p of that table is 1.1e-5: the permutation floor is 1/10001);
    a seed fixes the p-value; counts are checked and named."""
    # (8, 10), (2, 10): pooled rate 0.5, each cell off by 3 successes: 2 * 9 / 2.5 = 7.2
    result = equal_rates([(8, 10), (2, 10)], permutations=2000)
    assert result.chi2 == pytest.approx(7.2) and result.df == 1
    assert 0.005 < result.p < 0.03  # Fisher's exact two-sided p of this table: 0.023
    assert equal_rates([(5, 10)] * 10).p == 1.0
    assert equal_rates([(0, 10)] * 4).chi2 == 0.0
    extreme = equal_rates([(10, 10), (0, 10)])
    assert extreme.p == pytest.approx(1 / 10_001)
    assert equal_rates([(7, 10), (3, 10), (5, 10)]) == equal_rates([(7, 10), (3, 10), (5, 10)])
    with pytest.raises(ValueError, match="counts: expected at least 2 rates to compare, got 1"):
        equal_rates([(1, 2)])
    with pytest.raises(ValueError, match="successes of rate 1: expected an int in"):
        equal_rates([(1, 2), (3, 2)])


def test_spearman_ranks_ties_and_constants():
    assert spearman([1, 2, 3, 4], [10, 20, 30, 40]) == pytest.approx(1.0)
    assert spearman([1, 2, 3, 4], [4, 3, 2, 1]) == pytest.approx(-1.0)
    # ties share the mean rank: ranks (1.5, 1.5, 3, 4) and (1, 2, 3, 4): r = 4.5 / sqrt(4.5 * 5)
    assert spearman([0.3, 0.3, 2.0, 9.0], [1, 2, 3, 4]) == pytest.approx(4.5 / math.sqrt(4.5 * 5))
    assert math.isnan(spearman([1, 1, 1], [1, 2, 3]))
    with pytest.raises(ValueError, match="got 3 and 2"):
        spearman([1, 2, 3], [1, 2])
