"""Intervals and tests: Wilson, McNemar, Newcombe's paired interval; the statistics load without a simulator."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from nsl.errors import ConfigError
from nsl.eval import compare_paired, mcnemar_exact, paired_difference_interval, wilson_interval


def _wilson_reference(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """The textbook form: (k + z^2/2 -+ z sqrt(k(n-k)/n + z^2/4)) / (n + z^2)."""
    root = z * math.sqrt(k * (n - k) / n + z * z / 4)
    return (k + z * z / 2 - root) / (n + z * z), (k + z * z / 2 + root) / (n + z * z)


@pytest.mark.parametrize(
    "k, n, expected",
    [
        (8, 10, (0.490, 0.943)),
        (0, 10, (0.000, 0.278)),
        (10, 10, (0.722, 1.000)),
        (50, 100, (0.404, 0.596)),
        (1, 50, (0.004, 0.105)),
    ],
)
def test_wilson_interval_matches_known_values(k, n, expected):
    lo, hi = wilson_interval(k, n)
    assert (round(lo, 3), round(hi, 3)) == expected
    ref = _wilson_reference(k, n)
    assert lo == pytest.approx(max(0.0, ref[0]), abs=1e-12) and hi == pytest.approx(min(1.0, ref[1]), abs=1e-12)


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


def _modules_after(statement: str) -> set[str]:
    code = f"import json, sys; {statement}; print(json.dumps(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return set(json.loads(out.stdout.splitlines()[-1]))


@pytest.mark.parametrize(
    "statement",
    [
        "from nsl.eval import wilson_interval, SuccessRate, markdown_table",
        "from nsl.eval import compare_paired, mcnemar_exact, continual_metrics, Rate, read_curve",
        "from nsl.catalog import Catalog, wilson_interval",
    ],
)
def test_statistics_import_no_simulator_and_no_torch(statement):
    loaded = _modules_after(statement)
    assert not {"mujoco", "torch", "nsl.collectors"} & loaded, statement
    assert "nsl.eval.stats" in loaded or "nsl.catalog" in loaded


def test_the_simulator_loads_when_evaluation_needs_it():
    assert "mujoco" in _modules_after("from nsl.eval import evaluate")


def test_one_wilson_interval_serves_evaluation_and_the_catalog():
    import nsl.catalog
    import nsl.stats

    assert nsl.eval.wilson_interval is nsl.stats.wilson_interval is nsl.catalog.wilson_interval
