"""Ranking candidate bases for a new task: measured transfer first, an offline proxy otherwise.

A proxy is a number per (checkpoint, target data) pair that needs no training, e.g. the Q-function's
ranking AUC of success labels on a few target episodes (how well the checkpoint already tells the
target's successes from its failures).  :func:`rank_correlation` says how far a proxy can be trusted:
Spearman's rank correlation between the proxy and the measured advantage over the same pairs.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass
from typing import Any

from nsl.errors import ConfigError

from .matrix import Pair


@dataclass(frozen=True)
class Correlation:
    """Spearman's rho of a proxy against the measured advantage, over ``n`` (source, target) pairs."""

    rho: float | None  # None: fewer than 3 pairs, or a constant column
    p_value: float | None
    n: int
    within_target: float | None  # mean over targets of rho among that target's sources (how suggest-base uses it)
    targets: int  # targets with at least 3 sources that entered ``within_target``

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def __str__(self) -> str:
        if self.rho is None:
            return f"Spearman rho: undefined ({self.n} pairs; at least 3 with varying values are needed)"
        within = (
            ""
            if self.within_target is None
            else f"; within a target {self.within_target:+.2f} (mean over {self.targets} targets)"
        )
        return f"Spearman rho {self.rho:+.2f} (p = {self.p_value:.3g}, {self.n} pairs){within}"


def _spearman(x: list[float], y: list[float]) -> tuple[float | None, float | None]:
    if len(x) < 3 or len(set(x)) < 2 or len(set(y)) < 2:
        return None, None
    from scipy import stats

    res = stats.spearmanr(x, y)
    rho, p = float(res.statistic), float(res.pvalue)
    return (None, None) if math.isnan(rho) else (rho, p)


def rank_correlation(proxy: Mapping[Pair, float | None], advantage: Mapping[Pair, float | None]) -> Correlation:
    """Spearman's rho between ``proxy[(src, dst)]`` and ``advantage[(src, dst)]`` over pairs that have both."""
    pairs = sorted(p for p in set(proxy) & set(advantage) if proxy[p] is not None and advantage[p] is not None)
    for p in pairs:
        if not (math.isfinite(proxy[p]) and math.isfinite(advantage[p])):
            raise ConfigError(f"rank correlation: pair {p[0]} -> {p[1]} has a non-finite value; drop it or fix it")
    rho, pval = _spearman([proxy[p] for p in pairs], [advantage[p] for p in pairs])
    by_target: dict[str, list[Pair]] = {}
    for p in pairs:
        by_target.setdefault(p[1], []).append(p)
    within = [
        r
        for ps in by_target.values()
        for r in [_spearman([proxy[p] for p in ps], [advantage[p] for p in ps])[0]]
        if r is not None
    ]
    return Correlation(rho, pval, len(pairs), sum(within) / len(within) if within else None, len(within))


@dataclass(frozen=True)
class Candidate:
    """One catalogued checkpoint as a base for a new task."""

    ref: str
    id: str
    shift: str  # the task it was trained for
    measured: float | None = None  # A(its task -> the new task), from a transfer matrix
    interval: tuple[float, float] | None = None
    proxy: float | None = None  # the offline proxy on the new task's data
    note: str = ""  # why a score is missing

    @property
    def basis(self) -> str:
        return "measured" if self.measured is not None else "proxy" if self.proxy is not None else "none"

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "basis": self.basis}


def rank_candidates(candidates: Iterable[Candidate]) -> list[Candidate]:
    """Measured candidates first (highest advantage first), then by proxy (highest first), then unscored.

    Ties go by ref.
    """

    def key(c: Candidate):
        if c.measured is not None:
            return (0, -c.measured, c.ref)
        if c.proxy is not None:
            return (1, -c.proxy, c.ref)
        return (2, 0.0, c.ref)

    return sorted(candidates, key=key)
