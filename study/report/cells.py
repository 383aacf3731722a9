"""The records' cells: success counts, seeds pooled, and their 95% intervals, all computed by ``nsl.stats``.

A success rate gets its 95% Wilson interval over its scenes; a cell pooled
over k training seeds on the same scenes counts each scene once (the seeds'
mean rate on its N scenes).  A difference of two cells recorded on the same
scenes gets Newcombe's paired interval when each is one run, and the
hierarchical paired bootstrap (``nsl.stats.hierarchical_gain``: seeds
resampled, then scenes, each scene kept with its pair) when either pools
several seeds; that interval covers seeds and scenes, with the one target
collection held fixed.  Cells without per-scene outcomes fall back to
Newcombe's interval for independent rates.  Also here: the eval structures
(continual matrix, curve rows, early-stopping choices) read from the records.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from nsl.eval import CurveRow, PerformanceMatrix, Rate, choose_steps
from nsl.stats import (
    hierarchical_gain,
    hierarchical_rate,
    newcombe_interval,
    newcombe_paired_interval,
    paired_counts,
    t_interval,
    wilson_interval,
)


@dataclass(frozen=True)
class Count:
    successes: int
    episodes: int
    outcomes: str | None = None  # "1"/"0" per episode in scene order, when the evaluation recorded them
    runs: int = 1  # training seeds (or rounds) pooled, each on the same scenes: episodes = runs x scenes

    @property
    def rate(self) -> float:
        return self.successes / self.episodes

    @property
    def scenes(self) -> int:
        return self.episodes // self.runs

    @property
    def ci(self) -> tuple[float, float]:
        """Wilson's interval over the distinct scenes: a pooled cell's mean rate on its N scenes, each counted once
        (it covers the scenes, not the seeds)."""
        return wilson_interval(self.rate * self.scenes, self.scenes)  # type: ignore[arg-type]

    def matrix(self, scenes: int | None = None):
        """The outcomes as a (runs, scenes) 0/1 array (``scenes`` infers the runs of an old record), or None."""
        import numpy as np

        if self.outcomes is None:
            return None
        n = scenes or self.scenes
        if n <= 0 or len(self.outcomes) % n:
            return None
        return np.frombuffer(self.outcomes.encode(), dtype=np.uint8).reshape(-1, n).astype(np.int8) - ord("0")

    def pct(self) -> str:
        lo, hi = self.ci
        return f"{100 * self.rate:.0f}% [{100 * lo:.0f}-{100 * hi:.0f}]"

    def to_dict(self) -> dict:
        out: dict[str, Any] = {"successes": self.successes, "episodes": self.episodes}
        if self.runs > 1:
            out["runs"] = self.runs
        return out if self.outcomes is None else {**out, "outcomes": self.outcomes}


def count(d: Mapping | None) -> Count | None:
    return None if not d else Count(int(d["successes"]), int(d["episodes"]), d.get("outcomes"), int(d.get("runs", 1)))


def pooled(items: Sequence[Mapping | None]) -> Count | None:
    """Several seeds' counts as one (None if any is missing); outcomes concatenated when every seed has them."""
    cs = [count(d) for d in items]
    if not cs or any(c is None for c in cs):
        return None
    outcomes = None if any(c.outcomes is None for c in cs) else "".join(c.outcomes for c in cs)
    runs = sum(c.runs for c in cs)
    same = len({c.scenes for c in cs}) == 1  # every seed on the same scenes: each scene counts once
    return Count(sum(c.successes for c in cs), sum(c.episodes for c in cs), outcomes, runs if same else 1)


def _paired(a: Count, b: Count):
    """The two cells' outcomes as (runs, scenes) arrays on the same scenes, or None when they cannot be paired.
    An old record without ``runs`` whose outcomes are a multiple of the other cell's is read as that many runs."""
    if a.outcomes is None or b.outcomes is None:
        return None
    n = min(a.scenes, b.scenes)
    if a.scenes != b.scenes and (max(a.scenes, b.scenes) % n or (a.runs > 1 and b.runs > 1)):
        return None
    x, y = a.matrix(n), b.matrix(n)
    return None if x is None or y is None else (x, y)


def seed_mean(items: Sequence[Mapping | None]) -> tuple[float, float] | None:
    """(mean success over seeds, half-width of its 95% t interval) with two or more seeds, else None."""
    cs = [count(d) for d in items]
    if len(cs) < 2 or any(c is None for c in cs):
        return None
    return t_interval([c.rate for c in cs])  # type: ignore[union-attr]


def rate_interval(c: Count) -> tuple[float, float]:
    """A cell's 95% interval: over seeds and scenes (hierarchical bootstrap) for several seeds with per-scene
    outcomes, else Wilson's over its distinct scenes."""
    x = c.matrix() if c.runs > 1 else None
    if x is None:
        return c.ci
    got = hierarchical_rate(x[None])
    return got.low, got.high


def seeds_cell(items: Sequence[Mapping | None]) -> str:
    """A cell over training seeds: the seeds' mean rate with its 95% interval over seeds and scenes (each scene
    counted once); without per-scene outcomes the seed mean ± its t interval (seeds only)."""
    c = pooled(items)
    if c is None:
        return "-"
    if c.runs > 1 and c.outcomes is not None:
        lo, hi = rate_interval(c)
        return f"{100 * c.rate:.0f}% [{100 * lo:.0f}-{100 * hi:.0f}]"
    m = seed_mean(items)
    if m is None:
        return c.pct()
    return f"{100 * m[0]:.0f}% ±{100 * m[1]:.0f} (seeds only)"


def diff_interval(a: Count, b: Count) -> tuple[float, float, float]:
    """(a - b, low, high) on the same scenes: Newcombe's paired interval when each cell is one run; the
    hierarchical paired bootstrap over seeds and scenes when either pools several runs (each scene once, runs
    paired in order when both pool the same number, every run against the other's one otherwise); Newcombe's
    interval for independent rates over the distinct scenes when the outcomes cannot be paired."""
    pair = _paired(a, b)
    if pair is not None:
        x, y = pair
        if len(x) == len(y) == 1:
            lo, hi = newcombe_paired_interval(*paired_counts(x[0], y[0]))
            return a.rate - b.rate, lo, hi
        if len(x) == len(y) or 1 in (len(x), len(y)):
            got = hierarchical_gain((x - y)[None], None)
            return got.mean, got.low, got.high
    lo, hi = newcombe_interval(a.rate * a.scenes, a.scenes, b.rate * b.scenes, b.scenes)  # type: ignore[arg-type]
    return a.rate - b.rate, lo, hi


def percent(c: Count | None) -> str:
    """A cell's rate with its Wilson interval, ``-`` when it has no count."""
    return "-" if c is None else c.pct()


def points(a: Count, b: Count) -> str:
    d, lo, hi = diff_interval(a, b)
    return f"{100 * d:+.0f} [{100 * lo:+.0f}, {100 * hi:+.0f}]"


def pretty(shift: str) -> str:
    return shift.replace("_", " ")


def curve_rows(rows: Sequence[Mapping] | None) -> list[CurveRow]:
    return [CurveRow.from_dict(r) for r in rows or []]


def rate_count(rate: Rate | None) -> Count | None:
    """A curve point's success as a count (None: not measured or its episodes unknown)."""
    if rate is None or not rate.episodes:
        return None
    return Count(round(rate.success_rate * rate.episodes), rate.episodes)


def mean_curve(by_seed: Mapping[str, Sequence[Mapping] | None], which: str) -> list[tuple[int, Count]]:
    """(step, pooled count over seeds) at the steps every seed evaluated; the seeds met the same scenes, so its
    interval counts each scene once (it covers the scenes, not the seeds: the curves have no per-scene outcomes)."""
    per_seed = []
    for rows in by_seed.values():
        d = {}
        for r in curve_rows(rows):
            c = rate_count(r.target if which == "target" else r.base)
            if c is not None:
                d[r.step] = c
        per_seed.append(d)
    if not per_seed or any(not d for d in per_seed):
        return []
    steps = sorted(set.intersection(*(set(d) for d in per_seed)))
    return [(s, pooled([d[s].to_dict() for d in per_seed])) for s in steps]  # type: ignore[misc]


def continual_matrix(records: Mapping[str, Any]) -> PerformanceMatrix | None:
    c = records.get("continual")
    if not c:
        return None
    rows = [r for r in c["cells"]]
    while rows and all(x is None for x in rows[-1]):
        rows.pop()  # stages not evaluated yet
    if not rows:
        return None
    success = [[None if x is None else count(x).rate for x in r] for r in rows]
    episodes = [[None if x is None else count(x).episodes for x in r] for r in rows]
    single = {s: count(v).rate for s, v in c["single"].items() if v is not None}
    stages = ["base", *c["tasks"][1:]][: len(rows)]
    return PerformanceMatrix(tuple(c["tasks"]), tuple(stages), success, episodes, "base", single or None)


def early_stop_choices(records: Mapping[str, Any]) -> dict[str, Any]:
    """Each planned criterion's choice on the recorded curve (None: the criterion produced no choice)."""
    plan = records["plan"]
    es = plan.get("early_stop")
    rows = curve_rows(records.get("early_stop"))
    if not es or not rows:
        return {}
    choices = choose_steps(rows, patience=es["patience"])
    out = {"best": choices.get("best"), "final": choices.get("final")}
    for c in es["criteria"]:
        out[c] = choices.get(c)
    return out
