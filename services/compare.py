"""Compare two methods from their catalogued evaluations: a results table with paired, hierarchical intervals.

A *side* is a list of checkpoints (the runs of one method or recipe).  For every shift asked for, each run's
per-scene outcomes are read from its catalogued evaluation (``nsl eval`` stores them: episode ``i`` is scene
``(seed, i)``), so the two sides must have been evaluated on the same scenes: the same scene seed and
episode count, test objects, fp32.  Nothing is evaluated here; a missing evaluation is an error naming the
``nsl eval`` command that makes it.

A side's runs are grouped by what each checkpoint records: its target collection (the last dataset of its
training data, the target by nsl's convention) and its training seed.  Where that grouping is not recorded,
not distinct or not balanced, each run counts as a seed of one collection, and the text of what the
interval covers says so.

Per shift: each side's success rate and the paired difference A - B with the hierarchical bootstrap of
:mod:`nsl.stats` (:func:`~nsl.stats.hierarchical_gain` when side B is one checkpoint,
:func:`~nsl.stats.hierarchical_difference` otherwise).  Across shifts: IQM, mean and optimality gap of each
side's run-shift success rates, and the probability of improvement P(A > B), through :mod:`nsl.aggregates`
(intervals over runs, scenes fixed); a performance-profile plot and a JSON of every number.
"""

from __future__ import annotations

import os
import re
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from nsl.aggregates import Estimate
from nsl.errors import ConfigError, UnknownReferenceError
from nsl.stats import HierarchicalGain

__all__ = ["Comparison", "ShiftComparison", "Side", "compare"]

SPLIT, PRECISION = "test", "fp32"  # the evaluations compared: test objects, policies acting in fp32
PROFILE_FILE, JSON_FILE = "profile.png", "compare.json"
AGGREGATE_NAMES = {"iqm": "IQM", "mean": "mean", "optimality_gap": "optimality gap"}


@dataclass(frozen=True)
class Side:
    """One side of a comparison: its runs (``ckpt:NAME@STEP`` and catalog ids) grouped into target collections,
    each holding the same number of training seeds (``groups`` holds run indices, collections x seeds)."""

    label: str
    runs: tuple[str, ...]
    ids: tuple[str, ...]
    collections: tuple[str, ...]
    groups: tuple[tuple[int, ...], ...]
    pooled: str = ""  # why the runs were counted as seeds of one collection ("" when grouped as recorded)

    def covers(self) -> str:
        """What varies between this side's runs, in words: ``"3 seeds x 2 collections"``."""
        if len(self.runs) == 1:
            return "1 run, fixed"
        c, s = len(self.groups), len(self.groups[0])
        if self.pooled:
            return f"{s} runs as seeds of one collection ({self.pooled})"
        return f"{s} seed{'s' if s > 1 else ' (fixed)'} x {c} collection{'s' if c > 1 else ' (fixed)'}"

    def to_dict(self) -> dict[str, Any]:
        return {
            "label": self.label,
            "runs": list(self.runs),
            "ids": list(self.ids),
            "collections": list(self.collections),
            "groups": [list(g) for g in self.groups],
            "pooled": self.pooled or None,
            "covers": self.covers(),
        }


@dataclass(frozen=True)
class ShiftComparison:
    """One shift: the scenes both sides were scored on, each side's success rate and the paired difference A - B
    (all :class:`~nsl.stats.HierarchicalGain`: mean, interval, what it covers); ``runs_a``/``runs_b`` are each
    run's success rate on the shift, in the side's run order."""

    shift: str
    seed: int
    episodes: int
    rate_a: HierarchicalGain
    rate_b: HierarchicalGain
    difference: HierarchicalGain
    covers: str
    runs_a: tuple[float, ...]
    runs_b: tuple[float, ...]

    def to_dict(self) -> dict[str, Any]:
        return {
            "seed": self.seed,
            "episodes": self.episodes,
            "a": self.rate_a.to_dict(),
            "b": self.rate_b.to_dict(),
            "difference": {**self.difference.to_dict(), "covers": self.covers},
            "runs_a": list(self.runs_a),
            "runs_b": list(self.runs_b),
        }


@dataclass(frozen=True)
class Comparison:
    """What :func:`compare` computed and wrote: per shift (:class:`ShiftComparison`), each side's aggregates across
    shifts (``{"iqm", "mean", "optimality_gap"}`` -> :class:`~nsl.aggregates.Estimate`), P(A > B), and the paths of
    the performance-profile plot and the JSON of every number."""

    a: Side
    b: Side
    shifts: dict[str, ShiftComparison]
    aggregates_a: dict[str, Estimate]
    aggregates_b: dict[str, Estimate]
    improvement: Estimate
    confidence: float
    reps: int
    profile: Path
    json: Path

    def lines(self) -> list[str]:
        """The printed table: one row per shift, then the aggregates across shifts, then what was written."""
        a, b = self.a.label, self.b.label
        pct = 100 * self.confidence
        out = [
            f"A = {a} ({self.a.covers()}): {', '.join(self.a.runs)}",
            f"B = {b} ({self.b.covers()}): {', '.join(self.b.runs)}",
            f"per shift: success (%) with {pct:g}% hierarchical paired bootstrap intervals; "
            "A - B in points, on the same scenes",
            f"{'shift':<28} {'scenes':<14} {'A':<20} {'B':<20} A - B",
        ]
        for name, s in self.shifts.items():
            out.append(
                f"{name:<28} {f'{s.seed} x {s.episodes}':<14} {_pct(s.rate_a):<20} {_pct(s.rate_b):<20} "
                f"{s.difference.points()}"
            )
            out.append(f"{'':<28} interval covers: {s.covers}")
        single = [x for x, side in (("A", self.a), ("B", self.b)) if len(side.runs) == 1]
        out.append(f"across {len(self.shifts)} shift(s), each run's success rate on each shift one score:")
        out.append(
            f"  ({pct:g}% stratified bootstrap intervals over runs within each shift, scenes fixed"
            + "".join(f"; {x} has one run, so its intervals are its point" for x in single)
            + ")"
        )
        for key, label in AGGREGATE_NAMES.items():
            ea, eb = self.aggregates_a[key], self.aggregates_b[key]
            out.append(f"  {label:<16} A {_est(ea, 100):<22} B {_est(eb, 100)}")
        out.append(f"  {'P(A > B)':<16} {_est(self.improvement, 1, '.2f')}")
        out.append(f"wrote {self.json} and {self.profile}")
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": "nsl.compare",
            "version": 1,
            "confidence": self.confidence,
            "reps": self.reps,
            "a": self.a.to_dict(),
            "b": self.b.to_dict(),
            "shifts": {k: v.to_dict() for k, v in self.shifts.items()},
            "aggregates": {
                "a": {k: v.to_dict() for k, v in self.aggregates_a.items()},
                "b": {k: v.to_dict() for k, v in self.aggregates_b.items()},
                "probability_of_improvement": self.improvement.to_dict(),
            },
            "profile": str(self.profile),
        }


def _pct(g: HierarchicalGain) -> str:
    return f"{100 * g.mean:.1f} [{100 * g.low:.1f}, {100 * g.high:.1f}]"


def _est(e: Estimate, scale: float, fmt: str = ".1f") -> str:
    return f"{scale * e.value:{fmt}} [{scale * e.low:{fmt}}, {scale * e.high:{fmt}}]"


def compare(
    a: str | Sequence[str],
    b: str | Sequence[str],
    *,
    shift: str | Sequence[str],
    episodes: int | None = None,
    seed: int | None = None,
    labels: Sequence[str] | None = None,
    out: str | Path | None = None,
    reps: int = 2000,
    confidence: float = 0.95,
    gap_level: float = 1.0,
) -> Comparison:
    """Compare side ``a`` with side ``b`` (checkpoint references: ``ckpt:NAME[@STEP|@best|@TAG]``, tags, ids) on
    ``shift`` (comma-separated specs, ``all`` or ``study``) from their catalogued evaluations.

    ``seed`` and ``episodes`` pick the scenes (scene seed and count); left out, the one set of scenes every run of
    both sides was evaluated on is used.  ``labels`` names the sides (default: their references).  ``out`` is the
    folder for ``profile.png`` and ``compare.json`` (default ``$NSL_HOME/comparisons/A-vs-B``).  ``reps``
    bootstrap replicates, ``confidence`` the intervals' level; the bootstraps are seeded, so the numbers repeat.
    ``gap_level``: the success rate the optimality gap is measured below (1.0; the base policy's base-task
    success, e.g. 0.87, asks how far each method falls short of the level it had before the shift).
    """
    import numpy as np

    from nsl import workspace
    from nsl.aggregates import aggregates, performance_profile, probability_of_improvement
    from nsl.catalog import Catalog
    from nsl.collectors import parse_shift_list
    from nsl.stats import hierarchical_difference, hierarchical_rate

    if reps < 10 or not 0 < confidence < 1:
        raise ConfigError(f"reps {reps} must be at least 10 and confidence {confidence} in (0, 1)")
    refs_a, refs_b = _refs(a, "A"), _refs(b, "B")
    names = list(labels) if labels else [_label(refs_a), _label(refs_b)]
    if len(names) != 2 or not all(names) or names[0] == names[1]:
        raise ConfigError(f"labels {names!r} must be two different names, one per side, e.g. recipe,base")
    texts = [shift] if isinstance(shift, str) else list(shift)
    shifts = list(dict.fromkeys(s.name for t in texts for s in parse_shift_list(t)))
    with Catalog() as cat:
        entries_a, entries_b = ([_resolve(cat, r) for r in refs] for refs in (refs_a, refs_b))
        side_a, side_b = _side(names[0], entries_a), _side(names[1], entries_b)
        found = {s: _outcomes(cat, s, entries_a + entries_b, seed, episodes) for s in shifts}

    rows: dict[str, ShiftComparison] = {}
    scores_a, scores_b = [], []
    for s in shifts:
        (scene_seed, n), outcomes = found[s]
        ox = np.array([[outcomes[i] for i in g] for g in side_a.groups], dtype=np.float64)
        k = len(side_a.runs)
        oy = np.array([[outcomes[k + i] for i in g] for g in side_b.groups], dtype=np.float64)
        diff = hierarchical_difference(ox, oy, confidence=confidence, n_boot=reps)
        runs_a = tuple(float(np.mean(outcomes[i])) for i in range(k))
        runs_b = tuple(float(np.mean(outcomes[k + i])) for i in range(len(side_b.runs)))
        scores_a.append(runs_a)
        scores_b.append(runs_b)
        rows[s] = ShiftComparison(
            s,
            scene_seed,
            n,
            hierarchical_rate(ox, confidence=confidence, n_boot=reps),
            hierarchical_rate(oy, confidence=confidence, n_boot=reps),
            diff,
            f"{n} scenes (paired); A: {side_a.covers()}; B: {side_b.covers()}",
            runs_a,
            runs_b,
        )
    if not 0.0 < gap_level <= 1.0:
        raise ConfigError(f"gap_level {gap_level!r} must be a success rate in (0, 1]; e.g. 0.87 or 1.0")
    agg_a = aggregates(scores_a, reps=reps, confidence=confidence, gap_level=gap_level)
    agg_b = aggregates(scores_b, reps=reps, confidence=confidence, gap_level=gap_level)
    improvement = probability_of_improvement(scores_a, scores_b, reps=reps, confidence=confidence)

    folder = (
        Path(out) if out is not None else workspace.home() / "comparisons" / f"{_slug(names[0])}-vs-{_slug(names[1])}"
    )
    folder.mkdir(parents=True, exist_ok=True)
    taus = np.linspace(0.0, 1.0, 101)
    profiles = {
        label: performance_profile(sc, taus.tolist(), reps=reps, confidence=confidence)
        for label, sc in ((names[0], scores_a), (names[1], scores_b))
    }
    profile = _plot_profile(profiles, taus, folder / PROFILE_FILE, len(shifts), confidence)
    result = Comparison(side_a, side_b, rows, agg_a, agg_b, improvement, confidence, reps, profile, folder / JSON_FILE)
    record = result.to_dict()
    record["profile_curves"] = {
        "taus": taus.tolist(),
        **{
            key: {"profile": p.tolist(), "low": lo.tolist(), "high": hi.tolist()}
            for key, (p, lo, hi) in zip(("a", "b"), profiles.values())
        },
    }
    workspace.atomic_write_json(result.json, record)
    return result


# --- the runs ------------------------------------------------------------------------------------------------------


def _refs(refs: str | Sequence[str], which: str) -> list[str]:
    items = refs.split(",") if isinstance(refs, str) else list(refs)
    out = [r.strip() if r.strip().startswith("ckpt:") else f"ckpt:{r.strip()}" for r in items if r.strip()]
    if not out:
        raise ConfigError(f"side {which} names no checkpoint; give checkpoint refs such as ckpt:harsh@best,ckpt:NAME")
    return out


def _resolve(cat, ref: str):
    """The catalog entry of ``ref``; an unknown one fails naming the reference as the user wrote it."""
    from .refs import resolve_init

    try:
        return resolve_init(cat, ref)
    except UnknownReferenceError as e:
        raise UnknownReferenceError(f"{ref}: {e.args[0] if e.args else e}") from None


def _label(refs: list[str]) -> str:
    """A side's default name: its one reference, else the references' common prefix with ``*``."""
    if len(refs) == 1:
        return refs[0]
    common = os.path.commonprefix(refs).rstrip("-_@.")
    return f"{common}*" if len(common) > len("ckpt:") else f"{refs[0]} +{len(refs) - 1}"


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text.removeprefix("ckpt:")).strip("_")[:60] or "side"


def _side(label: str, entries: list) -> Side:
    """Group a side's checkpoints by target collection (the last dataset trained on) and training seed."""
    runs = tuple(f"ckpt:{e.ref}" for e in entries)
    seen: dict[str, str] = {}
    for run, e in zip(runs, entries):
        if e.id in seen:
            raise ConfigError(f"{seen[e.id]} and {run} are the same checkpoint ({e.short_id}); give each run once")
        seen[e.id] = run
    keys, why = [], ""
    for run, e in zip(runs, entries):
        collection = f"{e.data[-1].dataset}@v{e.data[-1].version}" if e.data else None
        seed = (e.config.get("training") or {}).get("seed") if isinstance(e.config, dict) else None
        if (collection is None or seed is None) and not why:
            why = f"{run} records no {'training data' if collection is None else 'training seed'}"
        keys.append((collection, seed))
    if not why and len(set(keys)) < len(keys):
        (collection, seed), _ = Counter(keys).most_common(1)[0]
        why = f"several runs share target data {collection} and training seed {seed}"
    by: dict[str, list[int]] = {}
    for i, (collection, _) in enumerate(keys):
        by.setdefault(collection or "unrecorded", []).append(i)
    if not why and len({len(g) for g in by.values()}) > 1:
        why = "its target collections hold " + ", ".join(f"{len(g)} runs of {c}" for c, g in by.items())
    if why and len(entries) > 1:
        return Side(label, runs, tuple(e.id for e in entries), ("pooled",), (tuple(range(len(entries))),), why)
    return Side(label, runs, tuple(e.id for e in entries), tuple(by), tuple(tuple(g) for g in by.values()))


def _outcomes(cat, shift: str, entries: list, seed: int | None, episodes: int | None):
    """``((scene seed, episodes), [outcomes per run])`` on ``shift``: the one set of scenes every run was evaluated
    on (``seed``/``episodes`` narrow it), else a one-line error naming the runs, the scenes and the fix."""
    from .options import EvaluateOptions

    runs = [f"ckpt:{e.ref}" for e in entries]
    every: list[dict[tuple[int, int], list[int]]] = []  # per run: (scene seed, episodes) -> outcomes
    for e in entries:
        got = {}
        for ev in cat.evaluations(e.id, shift):
            text = ev.extra.get("outcomes") or ""
            if ev.split == SPLIT and ev.precision == PRECISION and len(text) == ev.episodes:
                got[(ev.seed, ev.episodes)] = [1 if c == "1" else 0 for c in text]
        every.append(got)
    sets = [
        {k for k in got if (seed is None or k[0] == seed) and (episodes is None or k[1] == episodes)} for got in every
    ]
    common = set.intersection(*sets)
    if len(common) == 1:
        key = common.pop()
        return key, [got[key] for got in every]
    if common:
        shown = ", ".join(f"seed {s} x {n} episodes" for s, n in sorted(common))
        raise ConfigError(
            f"every run was evaluated on {shift} on several sets of scenes ({shown}); "
            "pick one with --seed and --episodes"
        )
    counts = Counter(k for s in sets for k in s)
    if counts:  # the scenes most runs have (then the most episodes): the others are told to match them
        key = max(counts, key=lambda k: (counts[k], k[1], k[0]))
    else:
        d = EvaluateOptions()
        key = (d.seed if seed is None else seed, d.episodes if episodes is None else episodes)
    lacking = [i for i, s in enumerate(sets) if key not in s]
    todo = ",".join(runs[i] for i in lacking)
    make = f"nsl eval --checkpoint {todo} --shift {shift} --episodes {key[1]} --seed {key[0]}"
    has = "; ".join(
        f"{runs[i]} on " + ", ".join(f"seed {s} x {n}" for s, n in sorted(every[i])) for i in lacking if every[i]
    )
    if counts and has:
        raise ConfigError(
            f"A and B were not evaluated on the same scenes on {shift}: "
            f"{', '.join(runs[i] for i in range(len(runs)) if i not in lacking)} on seed {key[0]} x {key[1]} episodes, "
            f"{has}; evaluate on the same scenes with `{make}`"
        )
    raise UnknownReferenceError(
        f"{', '.join(runs[i] for i in lacking)} {'has' if len(lacking) == 1 else 'have'} no evaluation on {shift} "
        f"with per-scene outcomes (test objects, fp32, seed {key[0]}, {key[1]} episodes)"
        f"{f' (evaluated: {has})' if has else ''}; make it with `{make}`"
    )


# --- the plot ------------------------------------------------------------------------------------------------------


def _plot_profile(
    profiles: dict[str, tuple[Any, Any, Any]], taus: Any, path: Path, shifts: int, confidence: float
) -> Path:
    """rliable's performance profile: the fraction of run-shift success rates above each threshold, per side, with
    its stratified bootstrap band."""
    from nsl.eval import new_figure, save_png

    fig = new_figure(5.5, 3.8)
    ax = fig.subplots()
    for i, (label, (p, lo, hi)) in enumerate(profiles.items()):
        colour = f"C{i}"
        ax.plot(100 * taus, p, color=colour, lw=1.8, label=label, drawstyle="steps-post")
        ax.fill_between(100 * taus, lo, hi, color=colour, alpha=0.2, step="post", lw=0)
    ax.set_xlim(0, 100)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel(r"success rate threshold $\tau$ (%)")
    ax.set_ylabel(r"fraction of run-shift scores $> \tau$")
    ax.set_title(f"performance profile over {shifts} shift(s); {100 * confidence:g}% bands over runs", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return save_png(fig, path)
