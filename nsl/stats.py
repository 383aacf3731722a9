"""Every interval nsl reports, in one place: a core module that every layer may import.

* :func:`wilson_interval`: a success rate on ``n`` scenes (Wilson's score interval).
* :func:`newcombe_paired_interval`: the difference of two rates measured on the *same* scenes
  (Newcombe 1998, method 10, for paired proportions); :func:`newcombe_interval` the same for two
  independent rates (his hybrid score interval).
* :func:`t_interval`: a mean over a few independent runs (Student's t); it covers what varies between
  those runs and nothing else.
* :func:`hierarchical_gain`: a fine-tune's gain over the base on shared scenes, for several training
  seeds within several target collections; a hierarchical paired bootstrap whose interval covers the
  expected gain over scenes, seeds and target collections (see its docstring for the few-collection
  correction).  :func:`hierarchical_rate` is the same without a base (several seeds on the same scenes);
  :func:`hierarchical_difference` compares two sides that both have several runs (``nsl compare``).

Nothing here imports numpy or scipy at module level: ``import nsl`` and the catalog stay light.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

Z95 = 1.959963984540054  # the standard normal's 97.5% quantile: two-sided 95% intervals


def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval for a binomial proportion (95% by default); (0, 1) when ``n`` is 0."""
    if n <= 0:
        return 0.0, 1.0
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


def newcombe_paired_interval(both: int, only_a: int, only_b: int, neither: int, z: float = Z95) -> tuple[float, float]:
    """Newcombe's (1998, method 10) interval for success(A) - success(B) on paired outcomes (the same scenes)."""
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


def newcombe_interval(k1: int, n1: int, k2: int, n2: int, z: float = Z95) -> tuple[float, float]:
    """Newcombe's hybrid score interval for k1/n1 - k2/n2 from independent samples (method 10 with no pairing)."""
    p1, p2 = (k1 / n1 if n1 else 0.0), (k2 / n2 if n2 else 0.0)
    (l1, u1), (l2, u2) = wilson_interval(k1, n1, z), wilson_interval(k2, n2, z)
    d = p1 - p2
    return d - math.sqrt((p1 - l1) ** 2 + (u2 - p2) ** 2), d + math.sqrt((u1 - p1) ** 2 + (p2 - l2) ** 2)


def paired_counts(a: Sequence[Any], b: Sequence[Any]) -> tuple[int, int, int, int]:
    """(both, only_a, only_b, neither) of two equally long outcome sequences (truthy or "1"/"0" per scene)."""
    x = [o in (True, 1, "1") for o in a]
    y = [o in (True, 1, "1") for o in b]
    both = sum(i and j for i, j in zip(x, y))
    only_a = sum(i and not j for i, j in zip(x, y))
    only_b = sum(j and not i for i, j in zip(x, y))
    return both, only_a, only_b, len(x) - both - only_a - only_b


def t_quantile(df: float, confidence: float = 0.95) -> float:
    """Student's t quantile for a two-sided interval (scipy, imported on first use)."""
    from scipy import stats

    return float(stats.t.ppf(0.5 + confidence / 2, df))


def t_interval(values: Sequence[float], confidence: float = 0.95) -> tuple[float, float] | None:
    """(mean, half-width) of the Student-t interval of the mean of ``values``; None for fewer than two.

    It covers only what varies between the values (training seeds, say): whatever they share (the
    scenes they were scored on, the data they were trained on) is held fixed."""
    n = len(values)
    if n < 2:
        return None
    mean = sum(values) / n
    sd = math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1))
    return mean, t_quantile(n - 1, confidence) * sd / math.sqrt(n)


def welch_interval(a: Sequence[float], b: Sequence[float], confidence: float = 0.95) -> tuple[float, float]:
    """(mean(b) - mean(a), half-width of Welch's t interval) for two independent groups of runs."""
    ma, mb = sum(a) / len(a), sum(b) / len(b)
    va = sum((x - ma) ** 2 for x in a) / (len(a) - 1) / len(a)
    vb = sum((x - mb) ** 2 for x in b) / (len(b) - 1) / len(b)
    dof = (va + vb) ** 2 / (va**2 / (len(a) - 1) + vb**2 / (len(b) - 1)) if va + vb > 0 else 1.0
    return mb - ma, t_quantile(dof, confidence) * math.sqrt(va + vb)


def mean_gain_of_rates(cells: Sequence[tuple[float, float]], n: int, z: float = Z95) -> tuple[float, float, float]:
    """(mean, low, high) of the mean of (after - before) over cells of published rates, each measured on ``n``
    independent attempts: the binomial uncertainty of a source's table (normal approximation)."""
    gains = [a - b for a, b in cells]
    var = sum(a * (1 - a) / n + b * (1 - b) / n for a, b in cells) / len(cells) ** 2
    m = sum(gains) / len(gains)
    return m, m - z * math.sqrt(var), m + z * math.sqrt(var)


def compare_intervals(ours: tuple[float, float, float], source: tuple[float, float, float]) -> str:
    """ "holds", "fails" or "not resolvable": is ``ours`` (mean, low, high) at least ``source``'s, given both
    intervals?  The difference's interval combines the two half-widths (Newcombe's square-and-add)."""
    d = ours[0] - source[0]
    low = d - math.sqrt((ours[0] - ours[1]) ** 2 + (source[2] - source[0]) ** 2)
    high = d + math.sqrt((ours[2] - ours[0]) ** 2 + (source[0] - source[1]) ** 2)
    return "holds" if low >= 0 else "fails" if high < 0 else "not resolvable"


# --- the hierarchical paired bootstrap ------------------------------------------------------------------------------

LEVELS = ("collections", "seeds", "scenes")


@dataclass(frozen=True)
class HierarchicalGain:
    """A mean gain (or rate, without a base) with its interval and what the interval covers.

    ``shares`` splits the variance of ``mean`` between target collections, training seeds and scenes
    (moment estimates; they sum to 1).  ``varies`` names the levels the interval covers: a level with
    a single member (one collection) is held fixed."""

    mean: float
    low: float
    high: float
    collections: int
    seeds: int  # per collection
    scenes: int
    shares: dict[str, float]
    confidence: float = 0.95
    strata: int = 1  # shifts averaged (hierarchical_mean_gain); 1: one shift

    @property
    def varies(self) -> tuple[str, ...]:
        out = []
        if self.collections > 1:
            out.append("collections")
        if self.seeds > 1:
            out.append("seeds")
        return (*out, "scenes")

    def covers(self) -> str:
        """What the interval covers, in words: ``"scenes, 3 seeds, 2 collections"``."""
        parts = [f"{self.strata} shifts"] if self.strata > 1 else []
        parts.append(f"{self.scenes} scenes")
        parts.append(f"{self.seeds} seeds" if self.seeds > 1 else "1 seed (fixed)")
        parts.append(f"{self.collections} collections" if self.collections > 1 else "1 collection (fixed)")
        return ", ".join(parts)

    def points(self) -> str:
        """``+6.1 [+2.0, +10.3]`` in points."""
        return f"{100 * self.mean:+.1f} [{100 * self.low:+.1f}, {100 * self.high:+.1f}]"

    def to_dict(self) -> dict:
        return {
            "mean": self.mean,
            "low": self.low,
            "high": self.high,
            "collections": self.collections,
            "seeds": self.seeds,
            "scenes": self.scenes,
            "shares": dict(self.shares),
            "varies": list(self.varies),
            **({"strata": self.strata} if self.strata > 1 else {}),
        }


def hierarchical_gain(
    finetune: Any, base: Any | None, *, confidence: float = 0.95, n_boot: int = 2000, seed: int = 0
) -> HierarchicalGain:
    """The mean gain of fine-tunes over the base on shared scenes, with a hierarchical paired bootstrap interval.

    ``finetune``: outcomes (0/1) shaped ``(collections, seeds, scenes)``: every fine-tune (a training
    seed on a target collection) scored on the same scenes as ``base`` (``(scenes,)``).  With ``base``
    None the quantity is the fine-tunes' success rate itself (:func:`hierarchical_rate`).

    The estimand is the expected gain over the distribution of scenes, training seeds and target
    collections.  Each replicate resamples training seeds within each collection and then scenes (one
    draw of scene indices shared by every run and the base, so each scene keeps its pairing).  The
    collection level cannot be resampled honestly with few collections (two collections give three
    distinct resamples, and the NOTES' simulation measured 83-89% coverage for a nominal 95%): each
    replicate adds instead a collection deviation drawn from Student's t with ``collections - 1``
    degrees of freedom, scaled by the moment estimate of the variance between collections beyond what
    their seeds explain.  The seed deviations are inflated by sqrt(S/(S-1)), the small-sample
    correction of a bootstrap over S values.  The interval is the percentile interval of the
    replicates; with one collection it covers seeds and scenes only, with one seed scenes (and
    collections) only.  ``tests/test_stats_coverage.py`` measures its coverage.
    """
    import numpy as np

    ft = np.asarray(finetune, dtype=np.float64)
    if ft.ndim != 3 or 0 in ft.shape:
        raise ValueError(f"finetune outcomes must be shaped (collections, seeds, scenes); got {ft.shape}")
    b = None if base is None else np.asarray(base, dtype=np.float64)[None]
    got = hierarchical_gain_batch(ft[None], b, confidence=confidence, n_boot=n_boot, seed=seed)
    c, s, n = ft.shape
    return HierarchicalGain(
        float(got["mean"][0]),
        float(got["low"][0]),
        float(got["high"][0]),
        c,
        s,
        n,
        {k: float(got[k][0]) for k in LEVELS},
        confidence,
    )


def hierarchical_mean_gain(
    finetune: Any, base: Any, *, confidence: float = 0.95, n_boot: int = 2000, seed: int = 0
) -> HierarchicalGain:
    """The mean over strata (shifts) of :func:`hierarchical_gain`, with a bootstrap stratified by shift.

    ``finetune`` is ``(shifts, collections, seeds, scenes)`` and ``base`` ``(shifts, scenes)``: each shift's
    fine-tunes and the base on the same scene seed.  Every shift is resampled on its own (its collections'
    deviation, its seeds), except the scenes: the shifts share one scene draw per replicate, since scene i
    is the same objects and poses on every shift and its difficulty carries across them.  The replicate
    is the mean of the shifts' gains.  ``shares`` splits the variance of the mean the same way.

    The collections enter at the level of the mean: each shift's collections are independent of the
    others', so the mean's collection variance is the sum of the shifts' moment estimates over shifts²,
    and its Student-t deviation pools their degrees of freedom, shifts x (collections - 1) (five shifts
    of two collections: 5, where one shift alone has 1), as a pooled variance estimate does when the
    collections vary about as much on every shift.  Drawing one t(1) deviation per shift instead, or
    taking the Welch-Satterthwaite degrees of freedom of five one-degree estimates, over-covers the mean
    (99-100% for a nominal 95%; ``tests/test_stats_coverage.py`` measures the coverage)."""
    import numpy as np

    ft = np.asarray(finetune, dtype=np.float64)
    b = np.asarray(base, dtype=np.float64)
    if ft.ndim != 4 or 0 in ft.shape or b.shape != (ft.shape[0], ft.shape[3]):
        raise ValueError(
            f"finetune must be shaped (shifts, collections, seeds, scenes) and base (shifts, scenes); "
            f"got {ft.shape} and {b.shape}"
        )
    got = hierarchical_gain_batch(
        ft,
        b,
        confidence=confidence,
        n_boot=n_boot,
        seed=seed,
        chunk=ft.shape[0],
        shared_scenes=True,
        collection_term=False,
    )
    k, c, s, n = ft.shape
    reps = got["replicates"].mean(axis=0)
    v = got["v_collections"]  # each shift's collection variance of its gain
    if c > 1 and v.sum() > 0:
        df = float(k * (c - 1))  # the shifts' collection variances pooled: k (c - 1) degrees of freedom
        rng = np.random.default_rng([seed, 1])
        reps = reps + rng.standard_t(df, size=reps.shape) * math.sqrt(v.sum()) / k
    alpha = (1 - confidence) / 2
    lo, hi = np.quantile(reps, [alpha, 1 - alpha])
    parts = {lvl: float(got["v_" + lvl].sum()) / k**2 for lvl in ("collections", "seeds")}
    scene_means = (ft - b[:, None, None, :]).mean(axis=(0, 1, 2))  # each scene's gain, averaged over everything
    parts["scenes"] = float(scene_means.var(ddof=1) / n) if n > 1 else 0.0
    total = sum(parts.values()) or 1.0
    return HierarchicalGain(
        float(got["mean"].mean()),
        float(lo),
        float(hi),
        c,
        s,
        n,
        {lvl: parts[lvl] / total for lvl in LEVELS},
        confidence,
        strata=k,
    )


def hierarchical_rate(outcomes: Any, *, confidence: float = 0.95, n_boot: int = 2000, seed: int = 0):
    """Several runs' success rate on shared scenes: :func:`hierarchical_gain` without a base, so each scene counts
    once however many runs met it."""
    return hierarchical_gain(outcomes, None, confidence=confidence, n_boot=n_boot, seed=seed)


def hierarchical_difference(
    a: Any, b: Any, *, confidence: float = 0.95, n_boot: int = 2000, seed: int = 0
) -> HierarchicalGain:
    """Success of side A minus success of side B on shared scenes, each side several runs: a paired bootstrap.

    ``a`` and ``b`` are outcomes (0/1) shaped ``(collections, seeds, scenes)``, every run of both sides scored
    on the same scenes.  The point is mean(A) - mean(B).  With one run on side B this *is*
    :func:`hierarchical_gain` (A's gain over B).  Otherwise each replicate resamples each side as
    :func:`hierarchical_gain` resamples its fine-tunes (seeds within collections, inflated by sqrt(S/(S-1));
    a Student-t deviation per side for its collections), the two sides independently, then draws the scenes
    once for both sides, so each scene keeps its pairing; the replicate is the difference of the sides'
    means over the drawn scenes.  Sides trained on the *same* target collections are treated as independent
    there, which widens the interval (conservative).  ``collections`` and ``seeds`` of the result are the
    larger side's, so ``varies`` names every level resampled on either side; ``shares`` adds the two sides'
    collection and seed variances."""
    import numpy as np

    x, y = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if x.ndim != 3 or y.ndim != 3 or 0 in x.shape or 0 in y.shape or x.shape[2] != y.shape[2]:
        raise ValueError(
            f"both sides' outcomes must be shaped (collections, seeds, scenes) on the same scenes; "
            f"got {x.shape} and {y.shape}"
        )
    if y.shape[:2] == (1, 1):
        return hierarchical_gain(x, y[0, 0], confidence=confidence, n_boot=n_boot, seed=seed)
    rng = np.random.default_rng(seed)
    n = x.shape[2]

    def side(o: Any) -> tuple[Any, float, float]:  # (replicate means per scene (n_boot, n), v_collections, v_seeds)
        c, s, _ = o.shape
        runs = o.mean(axis=2)
        colls = runs.mean(axis=1)
        within = float(((runs - colls[:, None]) ** 2).sum() / (c * (s - 1))) if s > 1 else 0.0
        v_colls = max(float(colls.var(ddof=1)) - within / s, 0.0) / c if c > 1 else 0.0
        counts = np.eye(s)[rng.integers(0, s, size=(n_boot, c, s))].sum(axis=2)  # (n_boot, c, s)
        scale = math.sqrt(s / (s - 1)) if s > 1 else 0.0
        weights = ((1.0 + scale * (counts - 1.0)) / (c * s)).reshape(n_boot, c * s)
        return weights @ o.reshape(c * s, n), v_colls, within / (c * s)

    (xa, ca, sa), (xb, cb, sb) = side(x), side(y)
    idx = rng.integers(0, n, size=(n_boot, n))  # one scene draw for both sides
    reps = np.take_along_axis(xa - xb, idx, axis=1).mean(axis=1)
    for o, v, sign in ((x, ca, 1.0), (y, cb, -1.0)):
        if o.shape[0] > 1:
            reps += sign * rng.standard_t(o.shape[0] - 1, size=n_boot) * math.sqrt(v)
    alpha = (1 - confidence) / 2
    lo, hi = np.quantile(reps, [alpha, 1 - alpha])
    scene = x.mean(axis=(0, 1)) - y.mean(axis=(0, 1))
    parts = {"collections": ca + cb, "seeds": sa + sb, "scenes": float(scene.var(ddof=1)) / n if n > 1 else 0.0}
    total = sum(parts.values()) or 1.0
    return HierarchicalGain(
        float(x.mean() - y.mean()),
        float(lo),
        float(hi),
        max(x.shape[0], y.shape[0]),
        max(x.shape[1], y.shape[1]),
        n,
        {lvl: parts[lvl] / total for lvl in LEVELS},
        confidence,
    )


def hierarchical_gain_batch(
    finetune: Any,
    base: Any | None,
    *,
    confidence: float = 0.95,
    n_boot: int = 2000,
    seed: int = 0,
    chunk: int = 8,
    shared_scenes: bool = False,
    collection_term: bool = True,
) -> dict[str, Any]:
    """:func:`hierarchical_gain` for many independent studies at once (vectorised; the coverage test's entry).

    ``finetune`` is ``(studies, collections, seeds, scenes)``, ``base`` ``(studies, scenes)`` or None.
    Returns arrays over studies: ``mean``, ``low``, ``high`` and the variance shares ``collections``,
    ``seeds``, ``scenes``, the variance components ``v_collections``, ``v_seeds``, ``v_scenes`` and, with
    ``shared_scenes`` (one scene draw per replicate for every study in a chunk: the studies are strata on
    the same scenes), the ``replicates`` ``(studies, n_boot)``.  ``collection_term=False`` leaves the
    collections' Student-t deviation out of the replicates (:func:`hierarchical_mean_gain` adds one for
    the mean instead).  Deterministic for a given ``seed``."""
    import numpy as np

    ft = np.asarray(finetune, dtype=np.float64)
    if ft.ndim != 4:
        raise ValueError(f"finetune outcomes must be shaped (studies, collections, seeds, scenes); got {ft.shape}")
    r_all, c, s, n = ft.shape
    d_all = ft if base is None else ft - np.asarray(base, dtype=np.float64)[:, None, None, :]
    rng = np.random.default_rng(seed)
    alpha = (1 - confidence) / 2
    k = c * s
    out: dict[str, Any] = {
        key: np.empty(r_all) for key in ("mean", "low", "high", *LEVELS, *(f"v_{lvl}" for lvl in LEVELS))
    }
    if shared_scenes:
        out["replicates"] = np.empty((r_all, n_boot))
    seed_scale = math.sqrt(s / (s - 1)) if s > 1 else 0.0
    onehot = np.eye(s)
    for start in range(0, r_all, chunk):
        d = d_all[start : start + chunk]
        r = d.shape[0]
        runs = d.mean(axis=3)  # (r, c, s): each run's mean
        colls = runs.mean(axis=2)  # (r, c)
        grand = colls.mean(axis=1)  # (r,)
        scene = d.mean(axis=(1, 2))  # (r, n): each scene's mean over runs
        v_scenes = scene.var(axis=1, ddof=1) / n if n > 1 else np.zeros(r)
        within = ((runs - colls[..., None]) ** 2).sum(axis=(1, 2)) / (c * (s - 1)) if s > 1 else np.zeros(r)
        v_seeds = within / k
        v_colls = np.maximum(colls.var(axis=1, ddof=1) - within / s, 0.0) / c if c > 1 else np.zeros(r)
        # seeds resampled within each collection (weights sum to 1 over the runs), deviations inflated
        picks = rng.integers(0, s, size=(r, n_boot, c, s))
        counts = onehot[picks].sum(axis=3)  # (r, B, c, s)
        weights = (1.0 + seed_scale * (counts - 1.0)) / k
        x = np.einsum("rbk,rkn->rbn", weights.reshape(r, n_boot, k), d.reshape(r, k, n))
        # scenes: one draw shared by every run and the base (and, with shared_scenes, by every study)
        idx = rng.integers(0, n, size=(1 if shared_scenes else r, n_boot, n))
        idx = np.broadcast_to(idx, (r, n_boot, n))
        reps = np.take_along_axis(x, idx, axis=2).mean(axis=2)
        if c > 1 and collection_term:
            reps += rng.standard_t(c - 1, size=(r, n_boot)) * np.sqrt(v_colls)[:, None]
        lo, hi = np.quantile(reps, [alpha, 1 - alpha], axis=1)
        total = v_colls + v_seeds + v_scenes
        safe = np.where(total > 0, total, 1.0)
        sl = slice(start, start + r)
        out["mean"][sl], out["low"][sl], out["high"][sl] = grand, lo, hi
        out["collections"][sl], out["seeds"][sl], out["scenes"][sl] = v_colls / safe, v_seeds / safe, v_scenes / safe
        out["v_collections"][sl], out["v_seeds"][sl], out["v_scenes"][sl] = v_colls, v_seeds, v_scenes
        if shared_scenes:
            out["replicates"][sl] = reps
    return out
