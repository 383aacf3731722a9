"""Comparing two policies: McNemar's exact test on paired episodes, Welch's t-test on seeds.

Two policies evaluated with the same ``EvalConfig.seed`` face the same scenes
(episode ``i`` uses scene seed ``(seed, i)``), so their per-episode outcomes
form pairs.  Only the discordant pairs (one policy succeeded, the other did
not) carry information about which is better: McNemar's exact test is the
two-sided binomial test of ``b`` successes-of-A-only against ``c``
successes-of-B-only with ``p = 1/2``.  The interval on the difference of the
two success rates is Newcombe's (1998) hybrid score interval for paired data
(his method 10), built from the two Wilson intervals.

For runs repeated over training seeds (the study's practice, Ch. 4.11),
:func:`welch_t_test` compares the per-seed success rates of two methods.

No scipy: the binomial and Student-t distributions are computed here with
``math`` (the t CDF through the regularised incomplete beta function).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from nsl.errors import ConfigError

from .success import Z95, wilson_interval


# --- distributions -------------------------------------------------------------------------------------------------

def binom_cdf(k: int, n: int, p: float = 0.5) -> float:
    """P(X <= k) for X ~ Binomial(n, p), summed exactly in log space."""
    if k < 0:
        return 0.0
    if k >= n:
        return 1.0
    if p <= 0.0:
        return 1.0
    if p >= 1.0:
        return 0.0
    lp, lq = math.log(p), math.log1p(-p)
    terms = [math.lgamma(n + 1) - math.lgamma(i + 1) - math.lgamma(n - i + 1) + i * lp + (n - i) * lq
             for i in range(k + 1)]
    top = max(terms)
    return min(1.0, math.exp(top) * sum(math.exp(t - top) for t in terms))


def _beta_continued_fraction(a: float, b: float, x: float) -> float:
    """The continued fraction of I_x(a, b), evaluated with the modified Lentz method."""
    tiny, eps = 1e-300, 1e-15
    c, d = 1.0, 1.0 - (a + b) * x / (a + 1.0)
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 500):
        m2 = 2 * m
        for num in (m * (b - m) * x / ((a + m2 - 1.0) * (a + m2)),
                    -(a + m) * (a + b + m) * x / ((a + m2) * (a + m2 + 1.0))):
            d = 1.0 + num * d
            d = 1.0 / (d if abs(d) > tiny else tiny)
            c = 1.0 + num / c
            c = c if abs(c) > tiny else tiny
            h *= d * c
        if abs(d * c - 1.0) < eps:
            break
    return h


def betainc(a: float, b: float, x: float) -> float:
    """The regularised incomplete beta function I_x(a, b) for a, b > 0 and 0 <= x <= 1."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    log_front = math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x)
    if x < (a + 1.0) / (a + b + 2.0):
        return math.exp(log_front) * _beta_continued_fraction(a, b, x) / a
    return 1.0 - math.exp(log_front) * _beta_continued_fraction(b, a, 1.0 - x) / b


def t_sf2(t: float, df: float) -> float:
    """Two-sided tail probability P(|T| >= |t|) of Student's t with ``df`` degrees of freedom."""
    if math.isinf(t):
        return 0.0
    return betainc(df / 2.0, 0.5, df / (df + t * t))


def t_quantile(q: float, df: float) -> float:
    """The ``q`` quantile of Student's t (0 < q < 1), by bisection on :func:`t_sf2`."""
    if not 0.0 < q < 1.0:
        raise ConfigError(f"quantile {q!r} is out of range; use 0 < q < 1 (e.g. 0.975)")
    if q == 0.5:
        return 0.0
    tail = 2.0 * min(q, 1.0 - q)  # two-sided tail beyond the quantile
    lo, hi = 0.0, 1.0
    while t_sf2(hi, df) > tail:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if t_sf2(mid, df) > tail:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-12 * max(1.0, hi):
            break
    t = 0.5 * (lo + hi)
    return t if q > 0.5 else -t


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
        return {**asdict(self), "success_a": self.success_a, "success_b": self.success_b,
                "difference": self.difference}

    def __str__(self) -> str:
        return (f"{self.name_a} - {self.name_b}: {100 * self.difference:+.1f} points "
                f"[{100 * self.ci_low:+.1f}, {100 * self.ci_high:+.1f}], McNemar p={self.p_value:.3g} "
                f"(discordant {self.only_a}/{self.only_b}, n={self.episodes})")


def mcnemar_exact(only_a: int, only_b: int) -> float:
    """Two-sided exact McNemar p-value from the discordant counts: 2 * P(X <= min) with X ~ Bin(b + c, 1/2)."""
    if only_a < 0 or only_b < 0:
        raise ConfigError(f"discordant counts must be non-negative; got {only_a} and {only_b}")
    n = only_a + only_b
    if n == 0:
        return 1.0
    return min(1.0, 2.0 * binom_cdf(min(only_a, only_b), n, 0.5))


def paired_difference_interval(both: int, only_a: int, only_b: int, neither: int,
                               z: float = Z95) -> tuple[float, float]:
    """Newcombe's (1998, method 10) interval for success(A) - success(B) on paired outcomes."""
    n = both + only_a + only_b + neither
    if n <= 0:
        return -1.0, 1.0
    p1, p2 = (both + only_a) / n, (both + only_b) / n
    l1, u1 = wilson_interval(both + only_a, n, z)
    l2, u2 = wilson_interval(both + only_b, n, z)
    margins = (both + only_a) * (only_b + neither) * (both + only_b) * (only_a + neither)
    phi = 0.0
    if margins > 0:
        cross = both * neither - only_a * only_b
        corrected = cross - n / 2 if cross > n / 2 else (cross if cross < 0 else 0.0)  # continuity correction
        phi = corrected / math.sqrt(margins)
    d = p1 - p2
    low = d - math.sqrt(max(0.0, (p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2))
    high = d + math.sqrt(max(0.0, (u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2) + (p2 - l2) ** 2))
    return max(-1.0, low), min(1.0, high)


def compare_paired(success_a: Sequence[bool], success_b: Sequence[bool], name_a: str = "A",
                   name_b: str = "B") -> PairedComparison:
    """Compare two policies from their per-episode outcomes on the same scenes (same order)."""
    a = np.asarray(success_a, dtype=bool).ravel()
    b = np.asarray(success_b, dtype=bool).ravel()
    if len(a) != len(b):
        raise ConfigError(f"paired outcomes need equal lengths; got {len(a)} for {name_a} and {len(b)} for "
                          f"{name_b}; evaluate both with the same --episodes and --seed")
    if len(a) == 0:
        raise ConfigError("paired comparison needs at least one episode; got none")
    both, only_a = int(np.sum(a & b)), int(np.sum(a & ~b))
    only_b, neither = int(np.sum(~a & b)), int(np.sum(~a & ~b))
    lo, hi = paired_difference_interval(both, only_a, only_b, neither)
    return PairedComparison(len(a), both, only_a, only_b, neither, mcnemar_exact(only_a, only_b), lo, hi,
                            name_a, name_b)


# --- repeated runs: Welch -------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class WelchResult:
    """Welch's unequal-variance t-test of mean(x) - mean(y), e.g. per-seed success rates of two methods."""

    mean_x: float
    mean_y: float
    t: float
    df: float  # Welch-Satterthwaite degrees of freedom
    p_value: float  # two-sided
    ci_low: float  # 95% interval on mean(x) - mean(y)
    ci_high: float

    @property
    def difference(self) -> float:
        return self.mean_x - self.mean_y

    def to_dict(self) -> dict:
        return {**asdict(self), "difference": self.difference}


def welch_t_test(x: Sequence[float], y: Sequence[float], confidence: float = 0.95) -> WelchResult:
    """Welch's t-test; each sample needs at least two values (e.g. success rates of 5 seeds)."""
    xs, ys = np.asarray(x, dtype=float).ravel(), np.asarray(y, dtype=float).ravel()
    if len(xs) < 2 or len(ys) < 2:
        raise ConfigError(f"Welch's t-test needs at least 2 values per sample; got {len(xs)} and {len(ys)} "
                          "(run more seeds)")
    if not (np.isfinite(xs).all() and np.isfinite(ys).all()):
        raise ConfigError("Welch's t-test got a NaN or infinite value; drop unfinished runs first")
    mx, my = float(xs.mean()), float(ys.mean())
    vx, vy = float(xs.var(ddof=1)) / len(xs), float(ys.var(ddof=1)) / len(ys)
    se = math.sqrt(vx + vy)
    diff = mx - my
    if se == 0.0:  # both samples constant
        df = float(len(xs) + len(ys) - 2)
        return WelchResult(mx, my, 0.0 if diff == 0 else math.copysign(math.inf, diff), df,
                           1.0 if diff == 0 else 0.0, diff, diff)
    df = (vx + vy) ** 2 / (vx ** 2 / (len(xs) - 1) + vy ** 2 / (len(ys) - 1))
    t = diff / se
    half = t_quantile(0.5 + confidence / 2.0, df) * se
    return WelchResult(mx, my, t, df, t_sf2(t, df), diff - half, diff + half)
