"""Intervals and tests: Wilson, McNemar, Newcombe's paired interval, Student t, Welch."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nsl.errors import ConfigError
from nsl.eval import compare_paired, mcnemar_exact, paired_difference_interval, welch_t_test, wilson_interval
from nsl.eval.paired import betainc, binom_cdf, t_quantile, t_sf2


def _wilson_reference(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """The textbook form: (k + z^2/2 -+ z sqrt(k(n-k)/n + z^2/4)) / (n + z^2)."""
    root = z * math.sqrt(k * (n - k) / n + z * z / 4)
    return (k + z * z / 2 - root) / (n + z * z), (k + z * z / 2 + root) / (n + z * z)


@pytest.mark.parametrize("k, n, expected", [
    (8, 10, (0.490, 0.943)),
    (0, 10, (0.000, 0.278)),
    (10, 10, (0.722, 1.000)),
    (50, 100, (0.404, 0.596)),
    (1, 50, (0.004, 0.105)),
])
def test_wilson_interval_matches_known_values(k, n, expected):
    lo, hi = wilson_interval(k, n)
    assert (round(lo, 3), round(hi, 3)) == expected
    ref = _wilson_reference(k, n)
    assert lo == pytest.approx(max(0.0, ref[0]), abs=1e-12) and hi == pytest.approx(min(1.0, ref[1]), abs=1e-12)


def test_binomial_cdf_is_exact():
    assert binom_cdf(3, 10) == pytest.approx(sum(math.comb(10, i) for i in range(4)) / 1024, rel=1e-12)
    assert binom_cdf(2, 5, 0.3) == pytest.approx(sum(math.comb(5, i) * 0.3 ** i * 0.7 ** (5 - i) for i in range(3)))
    assert binom_cdf(-1, 5) == 0.0 and binom_cdf(5, 5) == 1.0


def test_mcnemar_exact_on_a_hand_case():
    # discordant 1 vs 6: p = 2 * P(X <= 1 | Bin(7, 1/2)) = 2 * (1 + 7) / 128
    assert mcnemar_exact(1, 6) == pytest.approx(16 / 128)
    assert mcnemar_exact(6, 1) == pytest.approx(16 / 128)
    assert mcnemar_exact(0, 0) == 1.0 and mcnemar_exact(5, 5) == 1.0
    assert mcnemar_exact(0, 10) == pytest.approx(2 / 1024)


def test_compare_paired_counts_discordant_pairs():
    a = [1, 1, 1, 0, 1, 1, 0, 0, 1, 1]
    b = [1, 0, 0, 0, 1, 0, 0, 1, 0, 0]
    c = compare_paired(a, b, "new", "old")
    assert (c.both, c.only_a, c.only_b, c.neither) == (2, 5, 1, 2)
    assert c.difference == pytest.approx(0.4) and c.success_a == 0.7 and c.success_b == 0.3
    assert c.p_value == pytest.approx(mcnemar_exact(5, 1))
    assert c.ci_low < c.difference < c.ci_high
    assert "new - old" in str(c) and c.to_dict()["difference"] == pytest.approx(0.4)
    same = compare_paired(a, a)
    assert same.difference == 0 and same.p_value == 1.0


def test_newcombe_interval_matches_the_published_example():
    # Newcombe (1998), Stat. Med. 17:2635, example (a, b, c, d) = (36, 12, 2, 0): method 10 gives 0.0569 to 0.3404
    lo, hi = paired_difference_interval(36, 12, 2, 0)
    assert (round(lo, 4), round(hi, 4)) == (0.0569, 0.3404)


def test_paired_comparison_rejects_unequal_lengths():
    with pytest.raises(ConfigError, match="equal lengths.*same --episodes and --seed"):
        compare_paired([1, 0, 1], [1, 0])


def test_student_t_matches_closed_forms_and_tables():
    for t in (0.3, 1.0, 2.5, 10.0):
        assert t_sf2(t, 1) == pytest.approx(1 - 2 / math.pi * math.atan(t), rel=1e-9)  # Cauchy
        assert t_sf2(t, 2) == pytest.approx(1 - t / math.sqrt(2 + t * t), rel=1e-9)
    table = {1: 12.7062, 2: 4.3027, 5: 2.5706, 10: 2.2281, 30: 2.0423}
    for df, q in table.items():
        assert t_quantile(0.975, df) == pytest.approx(q, abs=1e-4)
    assert t_quantile(0.025, 10) == pytest.approx(-2.2281, abs=1e-4)
    assert betainc(2.0, 3.0, 0.4) == pytest.approx(0.5248, abs=1e-4)  # 1 - sum_{k<2} C(4,k) .4^k .6^(4-k)


def test_welch_t_test_by_hand():
    x, y = [0.6, 0.7, 0.65, 0.72, 0.68], [0.5, 0.55, 0.6, 0.52, 0.58]
    r = welch_t_test(x, y)
    vx, vy = np.var(x, ddof=1) / 5, np.var(y, ddof=1) / 5
    assert r.t == pytest.approx((np.mean(x) - np.mean(y)) / math.sqrt(vx + vy))
    assert r.df == pytest.approx((vx + vy) ** 2 / (vx ** 2 / 4 + vy ** 2 / 4))
    assert r.p_value == pytest.approx(t_sf2(r.t, r.df)) and r.p_value < 0.01
    half = t_quantile(0.975, r.df) * math.sqrt(vx + vy)
    assert (r.ci_low, r.ci_high) == pytest.approx((r.difference - half, r.difference + half))
    assert welch_t_test([0.5, 0.6, 0.7], [0.6, 0.5, 0.7]).p_value == pytest.approx(1.0)
    with pytest.raises(ConfigError, match="at least 2 values per sample"):
        welch_t_test([0.5], [0.4, 0.6])
