"""Aggregate metrics across shifts, after Agarwal et al. (2021) and their library ``rliable``: a thin adapter.

A score is one run's success rate on one shift (a run: a checkpoint, one training seed).  The
metrics are ``rliable.metrics``' own functions: the interquartile mean (IQM, the 25% trimmed mean of
every run-shift score), the mean (of each shift's mean over runs), the optimality gap (how far the
scores fall short of a level, scores above it counting as the level) and the probability of
improvement (P(X > Y) on a shift, Mann-Whitney with ties counting half, averaged over shifts).

Their intervals are rliable's stratified bootstrap: each replicate redraws the runs *within each
shift* (tasks are the strata, runs the units, as ``rly.StratifiedBootstrap`` does; the two sides of a
probability of improvement are redrawn independently, as ``rly.StratifiedIndependentBootstrap`` does),
and the interval is the replicates' percentile interval.  It covers what varies between runs and
nothing else: the scenes each run was scored on are held fixed (``nsl.stats`` has the intervals over
scenes).  Performance profiles are rliable's score distributions: the fraction of run-shift scores
above each threshold ``tau``.

Why not ``rliable.library``: it imports ``arch``, whose releases that rliable 1.2 accepts (< 8) fail
to import with pandas 3; the bootstrap is rebuilt here in a few lines of numpy, which also makes it
seeded (rliable draws from numpy's global generator).  Shifts may hold different numbers of runs
(``scores`` as one array per shift): IQM, the optimality gap and the profile then pool every run-shift
score, so a shift with more runs weighs more, as it would in rliable's matrix.

numpy, scipy and rliable are imported on first use: ``import nsl`` stays light.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["METRICS", "Estimate", "aggregates", "performance_profile", "probability_of_improvement"]

METRICS = ("iqm", "mean", "optimality_gap")


@dataclass(frozen=True)
class Estimate:
    """A point estimate with its stratified bootstrap interval (over runs; scenes fixed)."""

    value: float
    low: float
    high: float

    def to_dict(self) -> dict[str, float]:
        return {"value": self.value, "low": self.low, "high": self.high}


def _columns(scores: Any) -> list[Any]:
    """One 1-D float array of run scores per shift, from a ``(runs, shifts)`` array or a sequence of per-shift
    sequences (shifts may have different numbers of runs)."""
    import numpy as np

    if isinstance(scores, np.ndarray) and scores.ndim == 2:
        cols = [scores[:, j].astype(np.float64) for j in range(scores.shape[1])]
    else:
        cols = [np.asarray(c, dtype=np.float64).ravel() for c in scores]
    if not cols or any(c.size == 0 for c in cols):
        raise ValueError("scores need at least one shift with at least one run each")
    return cols


def _pooled(cols: Sequence[Any]):
    """Every run-shift score as rliable's ``(scores, 1)`` matrix (what its pooled metrics read)."""
    import numpy as np

    return np.concatenate(cols)[:, None]


def _metric(name: str, cols: Sequence[Any], gap_level: float) -> float:
    """rliable's own function for one metric of one side (the point estimate)."""
    from rliable import metrics

    if name == "iqm":
        return float(metrics.aggregate_iqm(_pooled(cols)))
    if name == "mean":  # the mean over shifts of each shift's mean over runs
        return float(sum(metrics.aggregate_mean(c[:, None]) for c in cols) / len(cols))
    if name == "optimality_gap":
        return float(metrics.aggregate_optimality_gap(_pooled(cols), gamma=gap_level))
    raise ValueError(f"unknown aggregate {name!r}; the aggregates are {', '.join(METRICS)}")


def _metric_rows(name: str, draws: Sequence[Any], gap_level: float) -> Any:
    """The same metric for every replicate at once: ``draws`` holds one ``(reps, runs)`` array per shift.  The
    formulas are rliable's (``tests/test_compare.py`` checks them against rliable's functions)."""
    import numpy as np
    from scipy import stats

    if name == "iqm":
        return stats.trim_mean(np.concatenate(draws, axis=1), proportiontocut=0.25, axis=1)
    if name == "mean":
        return np.mean([d.mean(axis=1) for d in draws], axis=0)
    if name == "optimality_gap":
        return gap_level - np.minimum(np.concatenate(draws, axis=1), gap_level).mean(axis=1)
    raise ValueError(f"unknown aggregate {name!r}; the aggregates are {', '.join(METRICS)}")


def _improvement_rows(dx: Sequence[Any], dy: Sequence[Any]) -> Any:
    """P(X > Y) for every replicate: per shift the share of (x, y) pairs with x > y, ties counting half (the
    Mann-Whitney U over the pairs, as rliable computes it), averaged over shifts."""
    import numpy as np

    per_shift = []
    for x, y in zip(dx, dy):
        a, b = x[:, :, None], y[:, None, :]
        per_shift.append(((a > b) + 0.5 * (a == b)).mean(axis=(1, 2)))
    return np.mean(per_shift, axis=0)


def _draws(cols: Sequence[Any], reps: int, rng: Any) -> list[Any]:
    """A stratified bootstrap of one side: each shift's runs redrawn with replacement, ``(reps, runs)`` per shift."""
    return [c[rng.integers(0, c.size, size=(reps, c.size))] for c in cols]


def _percentiles(values: Any, confidence: float) -> tuple[Any, Any]:
    import numpy as np

    alpha = (1 - confidence) / 2
    low, high = np.quantile(values, [alpha, 1 - alpha], axis=0)
    return low, high


def aggregates(
    scores: Any,
    *,
    gap_level: float = 1.0,
    reps: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> dict[str, Estimate]:
    """IQM, mean and optimality gap (below ``gap_level``) of ``scores`` across shifts, each with its stratified
    bootstrap interval: ``{"iqm": Estimate, "mean": ..., "optimality_gap": ...}``.

    ``scores``: success rates in [0, 1], a ``(runs, shifts)`` array or one sequence of runs per shift."""
    import numpy as np

    cols = _columns(scores)
    draws = _draws(cols, reps, np.random.default_rng(seed))
    out = {}
    for m in METRICS:
        low, high = _percentiles(_metric_rows(m, draws, gap_level), confidence)
        out[m] = Estimate(_metric(m, cols, gap_level), float(low), float(high))
    return out


def probability_of_improvement(
    x: Any, y: Any, *, reps: int = 2000, confidence: float = 0.95, seed: int = 0
) -> Estimate:
    """P(X > Y): on each shift the chance that a run of X scores above a run of Y (ties count half), averaged
    over shifts (``rliable.metrics.probability_of_improvement``), with its stratified bootstrap interval (each
    side's runs redrawn within each shift, independently).  ``x`` and ``y`` as ``scores`` in :func:`aggregates`,
    over the same shifts in the same order."""
    import numpy as np
    from rliable import metrics

    cx, cy = _columns(x), _columns(y)
    if len(cx) != len(cy):
        raise ValueError(f"x has {len(cx)} shifts and y {len(cy)}; give both sides' runs on the same shifts")
    point = sum(float(metrics.probability_of_improvement(a[:, None], b[:, None])) for a, b in zip(cx, cy)) / len(cx)
    rng = np.random.default_rng(seed)
    dx, dy = _draws(cx, reps, rng), _draws(cy, reps, rng)  # the two sides redrawn independently
    low, high = _percentiles(_improvement_rows(dx, dy), confidence)
    return Estimate(point, float(low), float(high))


def performance_profile(
    scores: Any, taus: Sequence[float], *, reps: int = 2000, confidence: float = 0.95, seed: int = 0
) -> tuple[Any, Any, Any]:
    """rliable's score distribution: for each ``tau``, the fraction of run-shift scores above it, with its
    stratified bootstrap band.  Returns three arrays shaped like ``taus``: profile, low, high."""
    import numpy as np

    cols = _columns(scores)
    t = np.asarray(taus, dtype=np.float64)
    profile = (_pooled(cols) > t[None, :]).mean(axis=0)  # rliable's run_score_deviation at each tau
    pooled = np.concatenate(_draws(cols, reps, np.random.default_rng(seed)), axis=1)  # (reps, scores)
    low, high = _percentiles((pooled[:, :, None] > t[None, None, :]).mean(axis=1), confidence)
    return profile, low, high
