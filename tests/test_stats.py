"""nsl.stats on hand-computed values: the t interval, Welch's, the source's binomial interval, verdicts."""

from __future__ import annotations

import pytest

from nsl.stats import compare_intervals, mean_gain_of_rates, newcombe_interval, t_interval, welch_interval


def test_t_interval_and_welch_by_hand():
    # 60, 70, 80: mean 70, sd 10, t(2) = 4.3027 -> half 24.84
    m, half = t_interval([60.0, 70.0, 80.0])
    assert m == pytest.approx(70.0) and half == pytest.approx(4.302653 * 10 / 3**0.5, rel=1e-6)
    assert t_interval([1.0]) is None
    d, h = welch_interval([1.0, 2.0, 3.0], [4.0, 5.0, 6.0])  # equal variances: df 4, t 2.7764, se sqrt(2/3)
    assert d == pytest.approx(3.0) and h == pytest.approx(2.776445 * (2 / 3) ** 0.5, rel=1e-6)


def test_independent_newcombe_and_the_sources_binomial_interval():
    lo, hi = newcombe_interval(30, 50, 20, 50)
    assert lo < 0.2 < hi and lo == pytest.approx(0.0044, abs=2e-3)  # Newcombe's hybrid score, 30/50 - 20/50
    m, lo, hi = mean_gain_of_rates([(0.9, 0.5)], 50)
    half = 1.959964 * ((0.9 * 0.1 + 0.5 * 0.5) / 50) ** 0.5
    assert m == pytest.approx(0.4) and (lo, hi) == pytest.approx((0.4 - half, 0.4 + half))


def test_verdicts_compare_two_uncertain_numbers():
    source = (0.27, 0.20, 0.34)
    assert compare_intervals((0.45, 0.40, 0.50), source) == "holds"  # resolvably above
    assert compare_intervals((0.05, 0.02, 0.08), source) == "fails"  # resolvably below
    assert compare_intervals((0.21, 0.18, 0.24), source) == "not resolvable"
