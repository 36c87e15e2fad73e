"""Statistics of success counts, for the benchmark's report: pure functions of integers, no dependencies.

- :func:`wilson_interval`: the Wilson score interval of a success rate (k successes in n episodes);
- :func:`fisher_exact`: the two-sided p-value of Fisher's exact test of a 2x2 table (two success rates);
- :func:`rate_difference`: the difference of two success rates with Newcombe's hybrid score interval
  (method 10 of Newcombe 1998, built from the two Wilson intervals);
- :func:`mantel_haenszel`: the p-value of two methods compared over several tasks at once (the
  Cochran-Mantel-Haenszel test, stratified by task);
- :func:`heterogeneity`: how much the difference between two methods varies from task to task (Cochran's
  Q on the per-task rate differences, and I^2);
- :func:`equal_rates`: whether several success rates differ more than chance would make them (Pearson's
  chi-squared of the k x 2 table, its p-value by permutation, exact enough for 10 episodes a rate);
- :func:`spearman`: Spearman's rank correlation of two measurements (e.g. a draw's success and its error).

Rates are fractions in [0, 1]; the report prints them as percentages.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from dataclasses import dataclass

Z_95 = 1.959963984540054
"""Standard normal quantile of 0.975: two-sided 95 % intervals."""


@dataclass(frozen=True)
class Estimate:
    """A rate or a difference of rates with its interval: ``low <= value <= high``, fractions."""

    value: float
    low: float
    high: float


def _check_counts(successes: int, n: int, which: str = "") -> None:
    """Counts must be ints with ``0 <= successes <= n`` and ``n >= 1``; errors name the argument."""
    for name, value in ((f"n{which}", n), (f"successes{which}", successes)):
        if isinstance(value, bool) or not isinstance(value, int):
            raise TypeError(f"{name}: expected an int, got {value!r}")
    if n < 1:
        raise ValueError(f"n{which}: expected at least 1 episode, got {n}")
    if not 0 <= successes <= n:
        raise ValueError(f"successes{which}: expected an int in [0, n{which}={n}], got {successes}")


def wilson_interval(successes: int, n: int, z: float = Z_95) -> Estimate:
    """The rate ``successes / n`` with its Wilson score interval (Wilson 1927; 95 % for the default ``z``).

    Unlike the normal approximation it stays inside [0, 1] and is not empty at 0 or n successes:
    0 of 10 gives [0, 0.278], 7 of 10 gives [0.397, 0.892].
    """
    _check_counts(successes, n)
    rate = successes / n
    z2 = z * z
    centre = (rate + z2 / (2 * n)) / (1 + z2 / n)
    half = z / (1 + z2 / n) * math.sqrt(rate * (1 - rate) / n + z2 / (4 * n * n))
    low = 0.0 if successes == 0 else centre - half  # exact ends where round-off would miss them
    high = 1.0 if successes == n else centre + half
    return Estimate(rate, low, high)


def fisher_exact(successes_1: int, n_1: int, successes_2: int, n_2: int) -> float:
    """Two-sided p-value of Fisher's exact test that two success rates are equal.

    The 2x2 table is ``[[successes_1, n_1 - successes_1], [successes_2, n_2 - successes_2]]``. Given its
    margins, the first cell is hypergeometric; the p-value sums the probabilities of every table at most as
    probable as the observed one (the usual two-sided rule, as R's ``fisher.test`` and SciPy's
    ``fisher_exact``). Computed exactly with integer binomial coefficients.
    """
    _check_counts(successes_1, n_1, "_1")
    _check_counts(successes_2, n_2, "_2")
    row, column, total = n_1, successes_1 + successes_2, n_1 + n_2

    # Table with x successes in row 1: its probability is weight(x) / comb(total, row).
    def weight(x: int) -> int:
        return math.comb(column, x) * math.comb(total - column, row - x)

    observed = weight(successes_1)
    tables = range(max(0, row + column - total), min(row, column) + 1)
    return sum(w for w in map(weight, tables) if w <= observed) / math.comb(total, row)


def rate_difference(successes_1: int, n_1: int, successes_2: int, n_2: int, z: float = Z_95) -> Estimate:
    """``rate_1 - rate_2`` with Newcombe's hybrid score interval (Newcombe 1998, method 10): the distances
    of each rate to the ends of its Wilson interval, combined in quadrature. 56/70 - 48/80 = 0.2 gives
    [0.0524, 0.3339] (Newcombe's example)."""
    _check_counts(successes_1, n_1, "_1")
    _check_counts(successes_2, n_2, "_2")
    first, second = wilson_interval(successes_1, n_1, z), wilson_interval(successes_2, n_2, z)
    difference = first.value - second.value
    low = difference - math.hypot(first.value - first.low, second.high - second.value)
    high = difference + math.hypot(first.high - first.value, second.value - second.low)
    return Estimate(difference, low, high)


Counts = tuple[int, int, int, int]
"""One stratum (a task) of a comparison: (successes_1, n_1, successes_2, n_2)."""


def chi2_sf(x: float, df: int) -> float:
    """P(X >= x) for X chi-squared with ``df`` (a positive int) degrees of freedom: the closed forms for
    integer degrees of freedom (Abramowitz and Stegun 26.4.4 and 26.4.5)."""
    if isinstance(df, bool) or not isinstance(df, int) or df < 1:
        raise ValueError(f"df: expected a positive int, got {df!r}")
    if x <= 0:
        return 1.0
    half = x / 2
    if df % 2 == 0:
        term, total = 1.0, 1.0
        for j in range(1, df // 2):
            term *= half / j
            total += term
        return min(1.0, math.exp(-half) * total)
    term, total = 1.0, 0.0
    for j in range(1, (df - 1) // 2 + 1):
        total += term
        term *= x / (2 * j + 1)
    return min(1.0, math.erfc(math.sqrt(half)) + math.sqrt(2 * x / math.pi) * math.exp(-half) * total)


def mantel_haenszel(strata: list[Counts]) -> float:
    """Two-sided p-value of the Cochran-Mantel-Haenszel test that two methods succeed equally often, with
    the tasks as strata (each task's 2x2 table kept apart, so a task where both do well cannot stand in for
    one where neither does); with the continuity correction, as R's ``mantelhaen.test``. Strata where
    every episode or none succeeded carry no information and count for nothing."""
    deviation = variance = 0.0
    for i, (s1, n1, s2, n2) in enumerate(strata):
        _check_counts(s1, n1, f"_1 of stratum {i}")
        _check_counts(s2, n2, f"_2 of stratum {i}")
        total, successes = n1 + n2, s1 + s2
        deviation += s1 - n1 * successes / total
        variance += n1 * n2 * successes * (total - successes) / (total * total * (total - 1))
    if variance == 0:
        return 1.0
    correction = 0.5 if abs(deviation) >= 0.5 else 0.0  # R's rule: no correction below half a success
    return chi2_sf((abs(deviation) - correction) ** 2 / variance, 1)


@dataclass(frozen=True)
class Heterogeneity:
    """Cochran's Q of per-stratum rate differences, its degrees of freedom and p-value, and I^2 (the share
    of the variation between strata beyond chance, 0..1)."""

    q: float
    df: int
    p: float
    i2: float


def heterogeneity(strata: list[Counts]) -> Heterogeneity:
    """Whether the difference ``rate_1 - rate_2`` is the same in every stratum: Cochran's Q with
    inverse-variance weights; each rate's variance uses (successes + 0.5) / (n + 1), so a stratum at 0 or
    n successes keeps a finite weight."""
    if len(strata) < 2:
        raise ValueError(f"strata: expected at least 2 to compare, got {len(strata)}")
    differences, weights = [], []
    for i, (s1, n1, s2, n2) in enumerate(strata):
        _check_counts(s1, n1, f"_1 of stratum {i}")
        _check_counts(s2, n2, f"_2 of stratum {i}")
        p1, p2 = (s1 + 0.5) / (n1 + 1), (s2 + 0.5) / (n2 + 1)
        differences.append(s1 / n1 - s2 / n2)
        weights.append(1 / (p1 * (1 - p1) / n1 + p2 * (1 - p2) / n2))
    mean = sum(w * d for w, d in zip(weights, differences, strict=True)) / sum(weights)
    q = sum(w * (d - mean) ** 2 for w, d in zip(weights, differences, strict=True))
    df = len(strata) - 1
    return Heterogeneity(q, df, chi2_sf(q, df), max(0.0, (q - df) / q) if q > 0 else 0.0)


@dataclass(frozen=True)
class EqualRates:
    """Pearson's chi-squared statistic of a k x 2 table of success counts, its degrees of freedom, and the
    permutation p-value of that statistic under equal rates."""

    chi2: float
    df: int
    p: float


def _pearson_chi2(successes: Sequence[int], sizes: Sequence[int]) -> float:
    total, hits = sum(sizes), sum(successes)
    if hits in (0, total):
        return 0.0  # every rate is 0 or every rate is 1: nothing differs
    rate = hits / total
    return sum((k - n * rate) ** 2 / (n * rate * (1 - rate)) for k, n in zip(successes, sizes, strict=True))


def equal_rates(counts: Sequence[tuple[int, int]], permutations: int = 10_000, seed: int = 0) -> EqualRates:
    """Whether the success rates ``counts`` = [(successes, episodes), ...] differ more than chance would
    make them: Pearson's chi-squared of the k x 2 table, its p-value the share of ``permutations`` random
    reassignments of the pooled outcomes to groups of the same sizes with a statistic at least as large
    (counting the observed one, so p > 0). The chi-squared distribution itself is poor with 10 episodes a
    group; the permutation needs no large counts. Seeded: the same counts give the same p."""
    if len(counts) < 2:
        raise ValueError(f"counts: expected at least 2 rates to compare, got {len(counts)}")
    for i, (k, n) in enumerate(counts):
        _check_counts(k, n, f" of rate {i}")
    successes, sizes = [k for k, _ in counts], [n for _, n in counts]
    observed = _pearson_chi2(successes, sizes)
    outcomes = [1] * sum(successes) + [0] * (sum(sizes) - sum(successes))
    generator = random.Random(seed)
    ends = [sum(sizes[: i + 1]) for i in range(len(sizes))]
    at_least = 0
    for _ in range(permutations):
        generator.shuffle(outcomes)
        groups = [sum(outcomes[end - n : end]) for end, n in zip(ends, sizes, strict=True)]
        at_least += _pearson_chi2(groups, sizes) >= observed - 1e-12
    return EqualRates(observed, len(counts) - 1, (at_least + 1) / (permutations + 1))


def _ranks(values: Sequence[float]) -> list[float]:
    """1-based ranks, ties given the mean of the ranks they span."""
    order = sorted(range(len(values)), key=lambda i: values[i])
    ranks = [0.0] * len(values)
    start = 0
    while start < len(order):
        end = start
        while end + 1 < len(order) and values[order[end + 1]] == values[order[start]]:
            end += 1
        for i in order[start : end + 1]:
            ranks[i] = (start + end) / 2 + 1
        start = end + 1
    return ranks


def spearman(x: Sequence[float], y: Sequence[float]) -> float:
    """Spearman's rank correlation of paired measurements (Pearson's correlation of their ranks, ties
    averaged), in [-1, 1]; NaN where either is constant (no order to correlate)."""
    if len(x) != len(y) or len(x) < 2:
        raise ValueError(f"x, y: expected two sequences of the same length >= 2, got {len(x)} and {len(y)}")
    rx, ry = _ranks(x), _ranks(y)
    mx, my = sum(rx) / len(rx), sum(ry) / len(ry)
    sxy = sum((a - mx) * (b - my) for a, b in zip(rx, ry, strict=True))
    sxx, syy = sum((a - mx) ** 2 for a in rx), sum((b - my) ** 2 for b in ry)
    return sxy / math.sqrt(sxx * syy) if sxx and syy else math.nan
