"""Comparing two policies on the same scenes: McNemar's exact test and Newcombe's paired interval.

Two policies evaluated with the same ``EvalConfig.seed`` face the same scenes
(episode ``i`` uses scene seed ``(seed, i)``), so their per-episode outcomes
form pairs.  Only the discordant pairs (one policy succeeded, the other did
not) carry information about which is better: McNemar's exact test is the
two-sided binomial test of ``b`` successes-of-A-only against ``c``
successes-of-B-only with ``p = 1/2``.  The interval on the difference of the
two success rates is Newcombe's (1998) hybrid score interval for paired data
(his method 10), built from the two Wilson intervals.

The exact binomial test comes from ``scipy.stats.binomtest``; Newcombe's
interval lives in ``nsl.stats`` with every other interval.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np
from scipy.stats import binomtest

from nsl.errors import ConfigError
from nsl.stats import newcombe_paired_interval

# --- paired episodes: McNemar ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PairedComparison:
    """A against B on the same scenes; ``difference`` is success(A) - success(B)."""

    episodes: int
    both: int  # episodes both policies succeeded
    only_a: int  # discordant: A succeeded, B failed
    only_b: int  # discordant: B succeeded, A failed
    neither: int
    p_value: float  # McNemar's exact two-sided test
    ci_low: float  # 95% interval on the difference (Newcombe's paired hybrid score)
    ci_high: float
    name_a: str = "A"
    name_b: str = "B"

    @property
    def success_a(self) -> float:
        return (self.both + self.only_a) / self.episodes

    @property
    def success_b(self) -> float:
        return (self.both + self.only_b) / self.episodes

    @property
    def difference(self) -> float:
        return (self.only_a - self.only_b) / self.episodes

    def to_dict(self) -> dict:
        return {**asdict(self), "success_a": self.success_a, "success_b": self.success_b, "difference": self.difference}

    def __str__(self) -> str:
        return (
            f"{self.name_a} - {self.name_b}: {100 * self.difference:+.1f} points "
            f"[{100 * self.ci_low:+.1f}, {100 * self.ci_high:+.1f}], McNemar p={self.p_value:.3g} "
            f"(discordant {self.only_a}/{self.only_b}, n={self.episodes})"
        )


def mcnemar_exact(only_a: int, only_b: int) -> float:
    """Two-sided exact McNemar p-value from the discordant counts: the binomial test of b against Bin(b + c, 1/2)."""
    if only_a < 0 or only_b < 0:
        raise ConfigError(f"discordant counts must be non-negative; got {only_a} and {only_b}")
    n = only_a + only_b
    if n == 0:
        return 1.0
    return float(binomtest(int(only_a), n, 0.5, alternative="two-sided").pvalue)


paired_difference_interval = newcombe_paired_interval  # Newcombe's (1998, method 10) paired interval, in nsl.stats


def compare_paired(
    success_a: Sequence[bool], success_b: Sequence[bool], name_a: str = "A", name_b: str = "B"
) -> PairedComparison:
    """Compare two policies from their per-episode outcomes on the same scenes (same order)."""
    a = np.asarray(success_a, dtype=bool).ravel()
    b = np.asarray(success_b, dtype=bool).ravel()
    if len(a) != len(b):
        raise ConfigError(
            f"paired outcomes need equal lengths; got {len(a)} for {name_a} and {len(b)} for "
            f"{name_b}; evaluate both with the same --episodes and --seed"
        )
    if len(a) == 0:
        raise ConfigError("paired comparison needs at least one episode; got none")
    both, only_a = int(np.sum(a & b)), int(np.sum(a & ~b))
    only_b, neither = int(np.sum(~a & b)), int(np.sum(~a & ~b))
    lo, hi = paired_difference_interval(both, only_a, only_b, neither)
    return PairedComparison(
        len(a), both, only_a, only_b, neither, mcnemar_exact(only_a, only_b), lo, hi, name_a, name_b
    )
