"""The study's report: tables beside the source study's figures, plots, and findings (a)-(e) with intervals.

Two steps.  :func:`gather` reads the finished units' outputs (catalogued
evaluations, curve files) into ``records.json``: plain counts, no derived
numbers.  Everything else is a pure function of those records (and so can be
tested on hand-made ones): the tables, the plots and :func:`findings`.

Intervals, all from ``nsl.stats``: a success rate gets its 95% Wilson
interval over its scenes; a cell pooled over k training seeds on the same
scenes counts each scene once (the seeds' mean rate on its N scenes).  A
difference of two cells recorded on the same scenes gets Newcombe's paired
interval when each is one run, and the hierarchical paired bootstrap
(``nsl.stats.hierarchical_gain``: seeds resampled, then scenes, each scene
kept with its pair) when either pools several seeds; that interval covers
seeds and scenes, with the one target collection held fixed.  Cells without
per-scene outcomes fall back to Newcombe's interval for independent rates.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from nsl.eval import (
    CriterionChoice,
    CurveRow,
    PerformanceMatrix,
    Rate,
    choose_steps,
    continual_metrics,
)
from nsl.stats import (
    compare_intervals,
    hierarchical_gain,
    hierarchical_rate,
    mean_gain_of_rates,
    newcombe_interval,
    newcombe_paired_interval,
    paired_counts,
    t_interval,
    wilson_interval,
)

from . import reference as ref
from .plan import Plan
from .units import BASE_POLICY, FEATURES_POLICY, continual_tags, no_target_tag, online_runs, online_tag, train_tag

REPORT_FILE = "report.md"
RECORDS_FILE = "records.json"
OFFLINE_CRITERIA = ("softopc", "auc", "td")


# --- counts ---------------------------------------------------------------------------------------------------------


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


def mean_gain_over_seeds(records: Mapping[str, Any], tier: str) -> tuple[float, float, int] | None:
    """The mean gain over the plan's shifts (tier ``tier`` minus the base policy) as (mean over seeds, half-width
    of its 95% t interval, seeds): each seed's five-shift mean is one sample.  None with fewer than two seeds
    measured on every shift."""
    bp = records["base_policy"]
    per_seed: list[list[float]] = []
    for shift, row in records["finetune"].items():
        b0 = count(bp.get(shift))
        cs = [count(d) for d in row["tiers"].get(tier, [])]
        if b0 is None or len(cs) < 2 or any(c is None for c in cs):
            return None
        per_seed.append([c.rate - b0.rate for c in cs])  # type: ignore[union-attr]
    k = min(len(g) for g in per_seed) if per_seed else 0
    if k < 2:
        return None
    got = t_interval([sum(g[i] for g in per_seed) / len(per_seed) for i in range(k)])
    return None if got is None else (got[0], got[1], k)


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


def points(a: Count, b: Count) -> str:
    d, lo, hi = diff_interval(a, b)
    return f"{100 * d:+.0f} [{100 * lo:+.0f}, {100 * hi:+.0f}]"


def _pretty(shift: str) -> str:
    return shift.replace("_", " ")


# --- gathering the records ------------------------------------------------------------------------------------------


def gather(plan: Plan, study: str, evaluation, read_curve_file, checkpoint=None) -> dict[str, Any]:
    """The study's raw numbers from its outputs: ``evaluation(ref, shift, episodes, seed)`` -> catalog entry or
    None; ``read_curve_file(checkpoint_name)`` -> list of CurveRow or None; ``checkpoint(ref)`` -> a checkpoint's
    folder or None (for the weight changes)."""
    e = plan.eval

    def ev(policy: str, shift: str) -> dict | None:
        r = plan.base if policy == BASE_POLICY else f"ckpt:{study}-{policy}@latest"
        entry = evaluation(r, shift, e.episodes, e.seed)
        if entry is None:
            return None
        out = {"successes": entry.successes, "episodes": entry.episodes}
        return {**out, "outcomes": entry.extra["outcomes"]} if entry.extra.get("outcomes") else out

    out: dict[str, Any] = {"study": study, "plan": plan.to_dict()}
    shifts = list(plan.shifts)
    extra = [
        *(plan.continual.sequence if plan.continual else ()),
        *([plan.curves.shift] if plan.curves else ()),
        *([plan.early_stop.shift] if plan.early_stop else ()),
    ]
    if plan.online is not None:
        extra.append(plan.online.shift)
    out["base_policy"] = {s: ev(BASE_POLICY, s) for s in dict.fromkeys(["base", *shifts, *extra])}
    if plan.online is not None:
        o = plan.online
        out["online"] = {
            online_key(method, ratio): {
                "method": method,
                "ratio": ratio,
                "grasps": [i * o.episodes for i in range(o.rounds + 1)],
                "success": [ev(BASE_POLICY, o.shift)]
                + [
                    ev(online_tag(method, ratio, o.shift, i, o.episodes, o.steps, o.seed), o.shift)
                    for i in range(1, o.rounds + 1)
                ],
            }
            for method, ratio in online_runs(plan)
        }
    f = plan.finetune
    top = f.tiers[-1]
    tiers = {}
    for shift in shifts:
        row: dict[str, Any] = {"tiers": {}, "tiers_base": {}, "baselines": {}, "baselines_base": {}}
        for k in f.tiers:
            tags = [train_tag("ft", shift, k, f.steps, s) for s in f.seeds_of(k)]
            row["tiers"][str(k)] = [ev(t, shift) for t in tags]
            row["tiers_base"][str(k)] = [ev(t, "base") for t in tags]
        for m in f.baselines:
            tags = [
                no_target_tag(f.steps, s) if m == "no_target" else train_tag(m, shift, top, f.steps, s) for s in f.seeds
            ]
            row["baselines"][m] = [ev(t, shift) for t in tags]
            row["baselines_base"][m] = [ev(t, "base") for t in tags]
        if f.cross_shift:  # the top tier on every shift of the plan
            tags = [train_tag("ft", shift, top, f.steps, s) for s in f.seeds]
            row["cross_shift"] = {other: [ev(t, other) for t in tags] for other in shifts}
        tiers[shift] = row
    out["finetune"] = tiers
    if f.base_task:  # Table 5.2's validation row, and the normaliser of Fig. 5.8
        out["base_task"] = {
            str(k): [ev(train_tag("ft", "base", k, f.steps, s), "base") for s in f.seeds_of(k)] for k in f.tiers
        }
        if checkpoint is not None:
            out["weight_change"] = weight_changes(plan, study, checkpoint)
    if plan.supervised is not None and checkpoint is not None:
        out["features"] = features_accuracy(checkpoint(f"ckpt:{study}-{FEATURES_POLICY}@latest"))
    if plan.continual is not None:
        c = plan.continual
        tasks = ["base", *c.sequence]

        def over_seeds(tags: Sequence[str], task: str) -> dict | None:  # a cell pools the seeds' sequences
            got = pooled([ev(t, task) for t in tags])
            return None if got is None else got.to_dict()

        stages = [[ev(BASE_POLICY, t) for t in tasks]]
        per_seed = [continual_tags(plan, seed) for seed in c.seeds]
        for i in range(len(c.sequence)):
            stages.append([over_seeds([tags[i] for tags in per_seed], t) for t in tasks])
        single = {
            s: over_seeds([train_tag("ft", s, c.episodes, c.steps, seed) for seed in c.seeds], s) for s in c.sequence
        }
        out["continual"] = {"tasks": tasks, "stages": ["base policy", *c.sequence], "cells": stages, "single": single}
        if len(c.seeds) > 1:  # each seed's own sequence, for the seed means and their t intervals
            out["continual"]["seeds"] = [
                [[ev(tags[i], t) for t in tasks] for i in range(len(c.sequence))] for tags in per_seed
            ]
            out["continual"]["single_seeds"] = {
                s: [ev(train_tag("ft", s, c.episodes, c.steps, seed), s) for seed in c.seeds] for s in c.sequence
            }
    if plan.curves is not None:
        cv = plan.curves
        curves = {}
        for m in cv.methods:
            curves[m] = {
                str(s): _rows(
                    read_curve_file(f"{study}-{train_tag(m, cv.shift, cv.episodes, cv.steps, s, prefix=f'curve-{m}')}")
                )
                for s in cv.seeds
            }
        out["curves"] = curves
    if plan.early_stop is not None:
        es = plan.early_stop
        out["early_stop"] = _rows(
            read_curve_file(f"{study}-{train_tag('ft', es.shift, es.episodes, es.steps, es.seed, prefix='es')}")
        )
    return out


def _rows(rows: Sequence[CurveRow] | None) -> list[dict] | None:
    return None if rows is None else [r.to_dict() for r in rows]


def _curve(rows: Sequence[Mapping] | None) -> list[CurveRow]:
    return [CurveRow.from_dict(r) for r in rows or []]


# --- tables ---------------------------------------------------------------------------------------------------------


def challenge_table(records: Mapping[str, Any]) -> str:
    """Table 5.1: the base policy on the base task and each shift, the drop in points, the study's figures."""
    plan = records["plan"]
    bp = records["base_policy"]
    base = count(bp.get("base"))
    lines = [
        "| task | base policy (ours) | change, points (ours) | study (real robot) | study change |",
        "|---|---|---|---|---|",
    ]
    lines.append(f"| base task | {'-' if base is None else base.pct()} | - | {ref.BASE_TASK}% | - |")
    for s in plan["shifts"]:
        c = count(bp.get(s))
        drop = "-" if c is None or base is None else points(c, base)
        study = ref.CHALLENGE.get(ref.study_shift(s))
        lines.append(
            f"| {_pretty(s)} | {'-' if c is None else c.pct()} | {drop} | "
            f"{'-' if study is None else f'{study}%'} | "
            f"{'-' if study is None else f'{study - ref.BASE_TASK:+d}'} |"
        )
    return "\n".join(lines)


def tiers_table(records: Mapping[str, Any]) -> str:
    """Table 5.2: target success by tier, the baselines at the top tier; a 'study' row under each shift."""
    plan = records["plan"]
    tiers = plan["finetune"]["tiers"]
    baselines = plan["finetune"]["baselines"]
    head = ["challenge", "", "base policy", *[str(k) for k in tiers], *[f"{m} ({tiers[-1]})" for m in baselines]]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for shift, row in records["finetune"].items():
        base = count(records["base_policy"].get(shift))
        cells = [_pretty(shift), "ours", "-" if base is None else base.pct()]
        cells += [seeds_cell(row["tiers"][str(k)]) for k in tiers]
        cells += [seeds_cell(row["baselines"].get(m, [])) for m in baselines]
        lines.append("| " + " | ".join(cells) + " |")
        study = ref.FINETUNE.get(ref.study_shift(shift))
        if study is not None:
            cells = [
                "",
                "study",
                f"{study['base']}%",
                *[f"{study[k]}%" if k in study else "-" for k in tiers],
                *[_study_baseline(study, m) for m in baselines],
            ]
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _study_baseline(study: Mapping[Any, int], baseline: str) -> str:
    """The study's figure for one of our baselines at its top tier (``-``: it has none)."""
    if baseline == "supervised_frozen":
        return f"{ref.SUPERVISED_FROZEN}%"
    key = ref.BASELINE_KEYS.get(baseline, baseline)
    return f"{study[key]}%" if key in study else "-"


def tiers_base_table(records: Mapping[str, Any]) -> str:
    """The same fine-tuned checkpoints on the base task (forgetting); the study's base-task row only as a note."""
    plan = records["plan"]
    tiers = plan["finetune"]["tiers"]
    baselines = plan["finetune"]["baselines"]
    base = count(records["base_policy"].get("base"))
    head = ["fine-tuned for", "base policy", *[str(k) for k in tiers], *[f"{m} ({tiers[-1]})" for m in baselines]]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for shift, row in records["finetune"].items():
        cells = [_pretty(shift), "-" if base is None else base.pct()]
        cells += [seeds_cell(row["tiers_base"][str(k)]) for k in tiers]
        cells += [seeds_cell(row["baselines_base"].get(m, [])) for m in baselines]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join([*lines, "", study_base_row_note()])


def study_base_row_note() -> str:
    """Why the study's base-task row of Table 5.2 is not beside our shift fine-tunes on the base task."""
    s = ref.FINETUNE["base"]
    figures = [
        f"base policy {s['base']}%",
        *[f"{k}: {s[k]}%" for k in ref.TIERS],
        *[f"{m} {s[m]}%" for m in s if isinstance(m, str) and m != "base"],
    ]
    return (
        "No study figure is put beside these rows: the study's base-task row of Table 5.2 ("
        + ", ".join(figures)
        + ") is a fine-tune on base-task data, not its shift fine-tunes evaluated on the base task, "
        "so it is not comparable to this table."
    )


def features_accuracy(folder: Path | None) -> dict[str, Any] | None:
    """What the supervised features' training measured (held-out and training accuracy, chance, classes, final
    loss), from its checkpoint at ``folder``; None until it exists or for imported weights (``--encoder``)."""
    from nsl.learners import read_config

    if folder is None:
        return None
    got = read_config(Path(folder)).get("data", {}).get("features")
    keys = ("classes", "heldout_accuracy", "train_accuracy", "chance", "final_loss")
    return {k: got[k] for k in keys} if got and all(k in got for k in keys) else None


def features_note(records: Mapping[str, Any]) -> str:
    """How well the supervised trunk learned its classification task, in one sentence ('' until measured)."""
    f = records.get("features")
    if not f or f["heldout_accuracy"] is None:
        return ""
    return (
        f"The supervised trunk classifies {100 * f['heldout_accuracy']:.1f}% of held-out frames of the "
        f"{f['classes']} train objects (chance {100 * f['chance']:.2f}%; {100 * f['train_accuracy']:.1f}% of its "
        f"training frames, final loss {f['final_loss']:.2f})."
    )


def weight_changes(plan: Plan, study: str, checkpoint) -> dict[str, dict[str, float]] | None:
    """Fig. 5.8: ``{shift: {layer: distance}}``, the cosine distance per layer between the base and its top-tier
    fine-tune on each shift (seed mean), divided by that of the fine-tune on the base task; None until all exist."""
    from nsl.learners import layer_distances

    f = plan.finetune
    top = f.tiers[-1]
    base = checkpoint(plan.base)
    if base is None:
        return None
    raw: dict[str, dict[str, float]] = {}
    for shift in ["base", *plan.shifts]:
        paths = [checkpoint(f"ckpt:{study}-{train_tag('ft', shift, top, f.steps, s)}@latest") for s in f.seeds]
        if any(p is None for p in paths):
            return None
        per_seed = [layer_distances(base, p) for p in paths]
        raw[shift] = {k: sum(d[k] for d in per_seed) / len(per_seed) for k in per_seed[0]}
    norm = raw.pop("base")
    return {s: {k: (v / norm[k] if norm[k] > 0 else float("nan")) for k, v in d.items()} for s, d in raw.items()}


def weight_change_table(records: Mapping[str, Any]) -> str:
    """Fig. 5.8 as a table: rows are layers, columns the shifts."""
    wc = records.get("weight_change")
    if not wc:
        return "(no weight changes yet: they need every top-tier fine-tune and the base-task fine-tune)"
    shifts = list(wc)
    layers = list(next(iter(wc.values())))
    lines = ["| layer | " + " | ".join(_pretty(s) for s in shifts) + " |", "|---|" + "---|" * len(shifts)]
    for layer in layers:
        lines.append(f"| {layer} | " + " | ".join(f"{wc[s][layer]:.2f}" for s in shifts) + " |")
    return "\n".join(lines)


def base_task_tiers_table(records: Mapping[str, Any]) -> str:
    """Table 5.2's base-task row: the base fine-tuned on base-task episodes it collected, beside the study's."""
    bt = records.get("base_task")
    if not bt:
        return "(no base-task fine-tunes: set finetune.base_task = true)"
    tiers = list(bt)
    b = count(records["base_policy"].get("base"))
    head = ["", "base policy", *tiers]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines.append(
        "| ours | " + ("-" if b is None else b.pct()) + " | " + " | ".join(seeds_cell(bt[t]) for t in tiers) + " |"
    )
    study = ref.FINETUNE["base"]
    lines.append(
        f"| study | {study['base']}% | "
        + " | ".join(f"{study[int(t)]}%" if int(t) in study else "-" for t in tiers)
        + " |"
    )
    return "\n".join(lines)


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


def continual_table(records: Mapping[str, Any]) -> str:
    """Table 5.3: each stage on its own task, vs the base policy, vs single-step fine-tuning; the study's numbers."""
    m = continual_matrix(records)
    if m is None:
        return "(no continual results yet)"
    c = records["continual"]
    cells = c["cells"]
    tasks = c["tasks"]
    lines = [
        "| stage task | continual (own stage) | vs base policy | single-step from base | vs single | final | "
        "study: own stage, each on its own task (Fig. 5.5) | study: vs its single (best Table 5.2 tier; 800 tier) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    T = len(m.stages) - 1
    for i, task in enumerate(tasks[1:], 1):
        j = tasks.index(task)
        own = count(cells[i][j]) if i <= T else None
        base = count(cells[0][j])
        single = count(c["single"].get(task))
        final = count(cells[T][j]) if T >= 1 else None
        study_task = ref.study_shift(task)
        seeds = c.get("seeds")  # several seeds: the seed mean with its t interval, then the pooled interval
        own_cell = seeds_cell([q[i - 1][j] for q in seeds]) if seeds and own is not None else own and own.pct()
        final_cell = seeds_cell([q[T - 1][j] for q in seeds]) if seeds and final is not None else final and final.pct()
        single_cell = seeds_cell(c["single_seeds"][task]) if seeds and single is not None else single and single.pct()
        cols = [
            _pretty(task),
            own_cell or "-",
            "-" if own is None or base is None else points(own, base),
            single_cell or "-",
            "-" if own is None or single is None else points(own, single),
            final_cell or "-",
            f"{ref.CONTINUAL.get(study_task, '-')}%",
            _study_vs_single(study_task),
        ]
        lines.append("| " + " | ".join(cols) + " |")
    b0, bT = count(cells[0][0]), count(cells[T][0])
    if b0 is not None and bT is not None:
        lines.append(
            f"| base task | {b0.pct()} (base policy) | - | - | - | {bT.pct()} ({points(bT, b0)}) | "
            f"no forgetting found | - |"
        )
    return "\n".join(lines)


def _study_vs_single(task: str) -> str:
    """The source's continual stage against its single-step baseline, the best tier of its Table 5.2, and against
    the 800 tier: ``-5 (vs 93% at 25); -19 vs 800's 69%``."""
    if task not in ref.CONTINUAL or task not in ref.SINGLE_BEST:
        return "-"
    best, tier = ref.SINGLE_BEST[task]
    top = ref.FINETUNE[task][ref.TOP]
    own = ref.CONTINUAL[task]
    return f"{own - best:+d} (vs {best}% at {tier}); {own - top:+d} vs {ref.TOP}'s {top}%"


def cross_shift_table(records: Mapping[str, Any]) -> str:
    """The top tier's fine-tunes on every shift: change against the base policy on that shift (seed mean)."""
    plan = records["plan"]
    shifts = plan["shifts"]
    rows = {s: r["cross_shift"] for s, r in records["finetune"].items() if r.get("cross_shift")}
    if not rows:
        return "(no cross-shift evaluations: set finetune.cross_shift = true)"
    head = ["fine-tuned for (rows), evaluated on (columns)", *[_pretty(s) for s in shifts]]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    base = [count(records["base_policy"].get(s)) for s in shifts]
    lines.append("| base policy | " + " | ".join("-" if b is None else b.pct() for b in base) + " |")
    for shift, row in rows.items():
        cells = []
        for other, b in zip(shifts, base):
            c = pooled(row[other])
            cells.append("-" if c is None else c.pct() + ("" if b is None else f" ({points(c, b)})"))
        lines.append(f"| {_pretty(shift)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def cross_shift_forgetting(records: Mapping[str, Any]) -> tuple[float, int] | None:
    """Mean change (fraction) of the top tier's fine-tunes on the shifts they were not trained on, and the pairs."""
    changes = []
    for shift, row in records["finetune"].items():
        for other, items in (row.get("cross_shift") or {}).items():
            c, b = pooled(items), count(records["base_policy"].get(other))
            if other != shift and c is not None and b is not None:
                changes.append(c.rate - b.rate)
    return (sum(changes) / len(changes), len(changes)) if changes else None


def matrix_table(records: Mapping[str, Any]) -> str:
    m = continual_matrix(records)
    if m is None:
        return "(no continual results yet)"
    lines = ["| after stage | " + " | ".join(_pretty(t) for t in m.tasks) + " |", "|---|" + "---|" * len(m.tasks)]
    for i, stage in enumerate(m.stages):
        cells = ["-" if m.rate(i, j) is None else m.rate(i, j).percent() for j in range(len(m.tasks))]
        lines.append(f"| {i}: {_pretty(stage)} | " + " | ".join(cells) + " |")
    metrics = continual_metrics(m)
    lines.append("")
    lines.append(
        f"Average forgetting {_pts(metrics.average_forgetting)} points, backward transfer "
        f"{_pts(metrics.average_backward_transfer)} points, average final success "
        f"{_pct(metrics.average_final_success)} (eval.continual's definitions)."
    )
    return "\n".join(lines)


def _pts(v: float | None) -> str:
    return "-" if v is None else f"{100 * v:+.0f}"


def _pct(v: float | None) -> str:
    return "-" if v is None else f"{100 * v:.0f}%"


def curves_table(records: Mapping[str, Any]) -> str:
    """Figs. 5.4/5.9 in numbers: per method, target and base-task success at the first, best and last point."""
    curves = records.get("curves")
    if not curves:
        return "(no method curves yet)"
    lines = [
        "| method | seeds | target at step 0 | best target (step) | target at last step | base task at last step "
        "| study (sim, Fig. 5.4) |",
        "|---|---|---|---|---|---|---|",
    ]
    for method, by_seed in curves.items():
        pts = mean_curve(by_seed, "target")
        basepts = mean_curve(by_seed, "base")
        if not pts:
            lines.append(f"| {method} | {len(by_seed)} | - | - | - | - | {ref.CURVES.get(method, '-')} |")
            continue
        best = max(pts, key=lambda p: (p[1].rate, -p[0]))
        lines.append(
            f"| {method} | {len(by_seed)} | {pts[0][1].pct()} | {best[1].pct()} ({best[0]}) | "
            f"{pts[-1][1].pct()} | {basepts[-1][1].pct() if basepts else '-'} | "
            f"{ref.CURVES.get(method, '-')} |"
        )
    return "\n".join(lines)


def mean_curve(by_seed: Mapping[str, Sequence[Mapping] | None], which: str) -> list[tuple[int, Count]]:
    """(step, pooled count over seeds) at the steps every seed evaluated; the seeds met the same scenes, so its
    interval counts each scene once (it covers the scenes, not the seeds: the curves have no per-scene outcomes)."""
    per_seed = []
    for rows in by_seed.values():
        d = {}
        for r in _curve(rows):
            rate = r.target if which == "target" else r.base
            if rate is not None and rate.episodes:
                d[r.step] = Count(round(rate.success_rate * rate.episodes), rate.episodes)
        per_seed.append(d)
    if not per_seed or any(not d for d in per_seed):
        return []
    steps = sorted(set.intersection(*(set(d) for d in per_seed)))
    return [(s, pooled([d[s].to_dict() for d in per_seed])) for s in steps]  # type: ignore[misc]


def early_stop_choices(records: Mapping[str, Any]) -> dict[str, Any]:
    """Each planned criterion's choice on the recorded curve (None: the criterion produced no choice)."""
    plan = records["plan"]
    es = plan.get("early_stop")
    rows = _curve(records.get("early_stop"))
    if not es or not rows:
        return {}
    choices = choose_steps(rows, patience=es["patience"])
    out = {"best": choices.get("best"), "final": choices.get("final")}
    for c in es["criteria"]:
        out[c] = choices.get(c)
    return out


def early_stop_table(records: Mapping[str, Any]) -> str:
    choices = early_stop_choices(records)
    if not choices:
        return "(no early-stopping curve yet)"
    lines = [
        "| criterion | chosen step | target success | base task | points below the best |",
        "|---|---|---|---|---|",
    ]
    best = choices.get("best")
    for name, c in choices.items():
        label = {"best": "best point (oracle)", "final": "last step (no stopping)"}.get(name, name)
        if c is None:
            lines.append(f"| {label} | no choice | - | - | - |")
            continue
        regret = "-" if c.target_regret is None else f"{100 * c.target_regret:.0f}"
        lines.append(
            f"| {label} | {c.step} | {'-' if c.target is None else c.target.percent()} | "
            f"{'-' if c.base is None else c.base.percent()} | {regret if best is not None else '-'} |"
        )
    return "\n".join(lines)


# --- findings -------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Finding:
    key: str  # a..e
    claim: str
    holds: bool | None  # None: not measured (no results yet, no choice, or too few scenes to resolve it)
    ours: str  # our numbers, with intervals
    study: str  # the study's numbers

    @property
    def verdict(self) -> str:
        if self.holds is None and "not resolvable" in self.ours:
            return "not resolvable"
        return {True: "holds", False: "fails", None: "not measured"}[self.holds]


def _over_seeds(records: Mapping[str, Any], tier: str) -> str:
    g = mean_gain_over_seeds(records, tier)
    if g is None:
        return ""
    m, half, k = g
    return f" [{100 * (m - half):+.1f}, {100 * (m + half):+.1f}] (mean over {k} seeds {100 * m:+.1f}, 95% t interval)"


def online_key(method: str, ratio: float) -> str:
    """A run of the online records: ``ft@0.5``."""
    return f"{method}@{ratio:g}"


def online_table(records: Mapping[str, Any]) -> str:
    """Figs. 5.10/5.11 as a table: each run's success after each round (round 0: the base policy)."""
    runs = records["online"]
    grasps = next(iter(runs.values()))["grasps"]
    head = ["round 1's method", "target share", *[f"{g:,} grasps" for g in grasps]]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    ratio = records["plan"]["online"]["ratio"]
    for run in sorted(runs.values(), key=lambda r: (r["ratio"] != ratio, r["method"], r["ratio"])):
        cells = [run["method"], f"{100 * run['ratio']:g}%"]
        cells += ["-" if (c := count(x)) is None else c.pct() for x in run["success"]]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def online_findings(records: Mapping[str, Any]) -> list[Finding]:
    """(h) Fig. 5.10: all parameters reach the base's base-task success, a new head does not; (i) Fig. 5.11: more
    target data adapts faster."""
    o, runs, out = records["plan"]["online"], records["online"], []
    base = count(records["base_policy"].get("base"))
    ft, head = runs.get(online_key("ft", o["ratio"])), runs.get(online_key("new_head", o["ratio"]))
    if ft is not None and head is not None:
        last_ft, last_head = count(ft["success"][-1]), count(head["success"][-1])
        holds, ours = None, "-"
        if base is not None and last_ft is not None and last_head is not None:
            reached = [
                g for g, x in zip(ft["grasps"][1:], ft["success"][1:]) if (c := count(x)) and c.rate >= base.ci[0]
            ]
            holds = last_ft.rate >= base.ci[0] and diff_interval(last_ft, last_head)[1] > 0
            ours = (
                f"after {ft['grasps'][-1]:,} grasps: all parameters {last_ft.pct()}, new head {last_head.pct()} "
                f"(difference {points(last_ft, last_head)}); the base's base-task success {base.pct()}, "
                + (f"first within its interval after {reached[0]:,} grasps" if reached else "not reached")
            )
        out.append(
            Finding(
                "h",
                "online rounds with all parameters reach the base policy's base-task success; with a new head they "
                "stay resolvably below",
                holds,
                ours,
                ref.ONLINE,
            )
        )
    ratios = sorted((r["ratio"], r) for r in runs.values() if r["method"] == "ft" and r["ratio"] in o["ratios"])
    if len(ratios) >= 2:
        (lo_r, low), (hi_r, high) = ratios[0], ratios[-1]
        a, b = pooled(high["success"][1:]), pooled(low["success"][1:])
        holds_i, ours_i = None, "-"
        if a is not None and b is not None:
            d, lo, hi = diff_interval(a, b)
            holds_i = True if lo > 0 else False if hi < 0 else None
            ours_i = (
                f"over rounds 1-{len(high['success']) - 1}: {100 * hi_r:g}% target data {a.pct()} against "
                f"{100 * lo_r:g}% {b.pct()}, {points(a, b)} points"
                + ("" if holds_i is not None else f" (not resolvable at {b.episodes} episodes)")
            )
        out.append(
            Finding("i", "more target data in each batch adapts faster (Fig. 5.11)", holds_i, ours_i, ref.ONLINE_RATIO)
        )
    return out


def findings(records: Mapping[str, Any]) -> list[Finding]:
    """Findings (a)-(e) on our numbers beside the study's, shift by shift in the plan's order."""
    plan = records["plan"]
    bp = records["base_policy"]
    base = count(bp.get("base"))
    out = []
    # (a) every shift costs the base policy at least 10 points
    drops = {s: (base, count(bp.get(s))) for s in plan["shifts"]}
    measured = {s: v for s, v in drops.items() if v[0] is not None and v[1] is not None}
    holds = (
        None
        if len(measured) < len(drops)
        else all(diff_interval(a, b)[0] >= 0.10 - 1e-12 for a, b in measured.values())
    )
    out.append(
        Finding(
            "a",
            "every shift costs the base policy at least 10 points",
            holds,
            "drops of " + "; ".join(f"{_pretty(s)} {points(a, b)}" for s, (a, b) in measured.items())
            if measured
            else "-",
            study_drops(plan["shifts"]),
        )
    )
    # (b) fine-tuning on the top tier gains at least the study's +27 points on average; reaches base on 2 of 5
    top = str(plan["finetune"]["tiers"][-1])
    gains, reached, parts = [], [], []
    for shift, row in records["finetune"].items():
        ft, b0 = pooled(row["tiers"][top]), count(bp.get(shift))
        if ft is None or b0 is None:
            continue
        gains.append(ft.rate - b0.rate)
        parts.append(f"{_pretty(shift)} {points(ft, b0)}")
        if base is not None and ft.rate >= base.rate:
            reached.append(shift)
    n = len(records["finetune"])
    verdict_b = ""
    if len(gains) < n:
        holds_b = None
    else:
        shift_gains = [diff_interval(pooled(r["tiers"][top]), count(bp.get(s))) for s, r in records["finetune"].items()]
        ours_b = mean_of_gains(shift_gains)  # type: ignore[arg-type]
        source_b = study_gain_interval(plan["shifts"])
        verdict_b = compare_intervals(ours_b, source_b)
        holds_b = {"holds": True, "fails": False}.get(verdict_b)
        verdict_b = (
            f"; against the study's binomial interval (N={ref.STUDY_N} per cell) "
            f"{100 * source_b[0]:+.1f} [{100 * source_b[1]:+.1f}, {100 * source_b[2]:+.1f}], ours "
            f"{100 * ours_b[0]:+.1f} [{100 * ours_b[1]:+.1f}, {100 * ours_b[2]:+.1f}] (shifts combined; each "
            f"shift's interval covers its training runs and scenes, one collection fixed): {verdict_b}"
        )
    out.append(
        Finding(
            "b",
            f"fine-tuning on {top} episodes gains at least as much as the study's (mean {ref.STUDY_MEAN_GAIN_800:+d} "
            f"points; reaches the base policy's base-task success on {len(ref.STUDY_REACHED_BASE)} of "
            f"{len(ref.CHALLENGE)} shifts)",
            holds_b,
            (
                f"mean {100 * sum(gains) / len(gains):+.0f} points{_over_seeds(records, top)} ({'; '.join(parts)}); "
                "reaches the base policy's "
                f"base-task success on {len(reached)} of {n}"
                + (f" ({', '.join(map(_pretty, reached))})" if reached else "")
                + verdict_b
            )
            if gains
            else "-",
            study_gains(plan["shifts"]),
        )
    )
    # (c) fine-tuning beats scratch at the top tier by 30 points or more
    parts, diffs = [], []
    for shift, row in records["finetune"].items():
        ft, sc = pooled(row["tiers"][top]), pooled(row["baselines"].get("scratch", []))
        if ft is None or sc is None:
            continue
        diffs.append(diff_interval(ft, sc)[0])
        parts.append(f"{_pretty(shift)} {points(ft, sc)}")
    has_scratch = "scratch" in plan["finetune"]["baselines"]
    holds_c = None if not has_scratch or len(diffs) < n else all(d >= 0.30 - 1e-12 for d in diffs)
    out.append(
        Finding(
            "c",
            f"fine-tuning beats scratch at {top} episodes by 30 points or more on every shift",
            holds_c,
            "; ".join(parts) or "-",
            study_over_scratch(plan["shifts"], top),
        )
    )
    # (d) the continual sequence loses 5 points or less on the base task
    holds_d, ours_d = None, "-"
    m = continual_matrix(records)
    if m is not None and plan.get("continual") and len(m.stages) == len(plan["continual"]["sequence"]) + 1:
        c = records["continual"]["cells"]
        b0, bT = count(c[0][0]), count(c[-1][0])
        if b0 is not None and bT is not None:
            d = diff_interval(b0, bT)
            holds_d = d[0] <= 0.05 + 1e-12
            ours_d = f"base task {b0.pct()} before, {bT.pct()} after the last stage: lost {points(b0, bT)} points"
            seeds = records["continual"].get("seeds")
            lost = [b0.rate - count(q[-1][0]).rate for q in seeds or [] if count(q[-1][0]) is not None]
            got = t_interval(lost) if len(lost) == len(seeds or []) else None
            if got is not None:
                mean, half = got
                ours_d += (
                    f" (mean over {len(lost)} seeds {100 * mean:+.1f} [{100 * (mean - half):+.1f}, "
                    f"{100 * (mean + half):+.1f}], 95% t interval)"
                )
    out.append(
        Finding(
            "d",
            "the continual sequence loses 5 points or less on the base task",
            holds_d,
            ours_d,
            ref.NO_FORGETTING,
        )
    )
    # (e) an offline stopping criterion lands within 5 points of the best point
    holds_e, ours_e = early_stop_finding(records)
    out.append(
        Finding(
            "e",
            "an offline stopping criterion lands within 5 points of the best point",
            holds_e,
            ours_e,
            f"not solved in the study ({_pretty(ref.EARLY_STOP_SHIFT)}, {ref.EARLY_STOP_ATTEMPTS} attempts: "
            f"{ref.EARLY_STOP})",
        )
    )
    # (f) a fine-tune for one shift loses success on the others: what a sequence of shifts must overcome
    if plan["finetune"].get("cross_shift"):
        cross = cross_shift_forgetting(records)
        out.append(
            Finding(
                "f",
                "a fine-tune for one shift loses success on the other shifts",
                None if cross is None else cross[0] < 0,
                "-"
                if cross is None
                else f"{100 * cross[0]:+.1f} points on average over {cross[1]} (shift, other) "
                "pairs against the base policy (the cross-shift table has each pair's interval)",
                "not measured in the study (its sequence found little forgetting of earlier shifts, Table 5.3)",
            )
        )
    # (g) RL pre-training beats supervised features at the top tier (Table 5.2's ImageNet column)
    supervised = [m for m in ("supervised", "supervised_frozen") if m in plan["finetune"]["baselines"]]
    if supervised:
        out.append(supervised_finding(records, supervised, top))
    if records.get("online"):
        out += online_findings(records)
    # (j) Fig. 5.8: even the morphological shifts change the convolutional layers
    if records["plan"]["finetune"].get("base_task"):
        out.append(weight_change_finding(records))
    return out


def _is_conv(layer: str) -> bool:
    return ".convs." in f".{layer}"


def weight_change_finding(records: Mapping[str, Any]) -> Finding:
    """(j): each shift's convolutional layers move further from the base than in a fine-tune on the base task
    (the mean over conv layers of Fig. 5.8's normalised distance above 1); point estimates of the seed mean."""
    wc = records.get("weight_change")
    holds, ours = None, "-"
    if wc:
        means = {s: [v for k, v in d.items() if _is_conv(k)] for s, d in wc.items()}
        means = {s: sum(v) / len(v) for s, v in means.items() if v}
        if means:
            holds = all(m > 1 for m in means.values())
            ours = "conv layers' mean distance against the base-task fine-tune's: " + ", ".join(
                f"{_pretty(s)} {m:.2f}x" for s, m in means.items()
            )
            ours += " (point estimates, no interval)"
    return Finding(
        "j", "every shift changes the convolutional layers more than a fine-tune on the base task", holds, ours,
        ref.WEIGHT_CHANGE,
    )  # fmt: skip


def supervised_finding(records: Mapping[str, Any], baselines: Sequence[str], top: str) -> Finding:
    """(g): the fine-tuned RL base against each supervised-features baseline, shift by shift, paired scenes."""
    parts, lows = [], []
    for shift, row in records["finetune"].items():
        ft = pooled(row["tiers"][top])
        cells = []
        for m in baselines:
            sv = pooled(row["baselines"].get(m, []))
            if ft is None or sv is None:
                continue
            lows.append(diff_interval(ft, sv)[1])
            cells.append(f"{'frozen' if m.endswith('frozen') else 'trained'} {sv.pct()}: {points(ft, sv)}")
        if cells:
            parts.append(f"{_pretty(shift)} RL {ft.pct()} against " + ", ".join(cells))
    expected = len(records["finetune"]) * len(baselines)
    holds = None if len(lows) < expected else all(lo > 0 for lo in lows)
    study = ", ".join(
        f"{_pretty(ref.study_shift(s))} {ref.FINETUNE[ref.study_shift(s)][ref.TOP]}% against "
        f"{ref.FINETUNE[ref.study_shift(s)]['imagenet']}%"
        for s in records["finetune"]
        if ref.study_shift(s) in ref.FINETUNE
    )
    note = features_note(records)
    return Finding(
        "g",
        f"RL pre-training beats supervised features at {top} episodes on every shift (features trained and frozen)",
        holds,
        ("; ".join(parts) or "-") + (f". {note}" if note else ""),
        f"{study}; frozen {ref.SUPERVISED_FROZEN}% ({ref.SUPERVISED_CONCLUSION})",
    )


def mean_of_gains(gains: Sequence[tuple[float, float, float]]) -> tuple[float, float, float]:
    """(mean, low, high) of the mean of independent shifts' gains, each (mean, low, high): half-widths added in
    quadrature (normal approximation; each shift has its own scenes and fine-tunes)."""
    m = sum(g[0] for g in gains) / len(gains)
    lo = math.sqrt(sum((g[0] - g[1]) ** 2 for g in gains)) / len(gains)
    hi = math.sqrt(sum((g[2] - g[0]) ** 2 for g in gains)) / len(gains)
    return m, m - lo, m + hi


def study_gain_interval(shifts: Sequence[str]) -> tuple[float, float, float]:
    """The study's mean gain at its top tier over the plan's shifts (all five when the plan names none of
    them), with the binomial interval of its N attempts per cell."""
    known = [ref.study_shift(s) for s in shifts if ref.study_shift(s) in ref.STUDY_GAINS] or list(ref.STUDY_GAINS)
    cells = [(ref.FINETUNE[s][ref.TOP] / 100, ref.FINETUNE[s]["base"] / 100) for s in known]
    return mean_gain_of_rates(cells, ref.STUDY_N)


def study_figures(shifts: Sequence[str], table: Mapping[str, int]) -> list[tuple[str, int | None]]:
    """The study's figure for each of the plan's shifts, in the plan's order (None: the study has none)."""
    return [(s, table.get(ref.study_shift(s))) for s in shifts]


def _signed(v: int | None) -> str:
    return "-" if v is None else f"{v:+d}"


def study_drops(shifts: Sequence[str]) -> str:
    """(a) in the study: the base policy's drop on each of the plan's shifts (Table 5.1) and their range."""
    figs = study_figures(shifts, ref.STUDY_DROPS)
    known = [v for _, v in figs if v is not None]
    listed = "; ".join(f"{_pretty(ref.study_shift(s))} {'-' if v is None else v}" for s, v in figs)
    return f"drops of {listed} points" + (f" ({min(known)}-{max(known)})" if known else "")


def study_gains(shifts: Sequence[str]) -> str:
    """(b) in the study: the top tier's gain on each of the plan's shifts (Table 5.2), its mean, who reached 86%."""
    figs = study_figures(shifts, ref.STUDY_GAINS)
    known = [(s, v) for s, v in figs if v is not None]
    listed = "; ".join(f"{_pretty(ref.study_shift(s))} {_signed(v)}" for s, v in figs)
    if not known:
        return f"gains at {ref.TOP} attempts: {listed} points"
    mean = f"mean {sum(v for _, v in known) / len(known):+.0f}"
    reached = [s for s, _ in known if ref.study_shift(s) in ref.STUDY_REACHED_BASE]
    every = sorted(ref.study_shift(s) for s, _ in known) == sorted(ref.STUDY_GAINS)
    if not every:
        mean += f"; {ref.STUDY_MEAN_GAIN_800:+d} over its {len(ref.STUDY_GAINS)} shifts"
    return (
        f"gains at {ref.TOP} attempts: {listed} points ({mean}); {len(reached)} of {len(known)} reached its "
        f"base-task {ref.BASE_TASK}%"
        + (f" ({', '.join(_pretty(ref.study_shift(s)) for s in reached)})" if reached else "")
        + ("" if every else f" ({len(ref.STUDY_REACHED_BASE)} of its {len(ref.CHALLENGE)})")
    )


def study_over_scratch(shifts: Sequence[str], top: str) -> str:
    """(c) in the study: fine-tuning minus scratch at its top tier on each of the plan's shifts (Table 5.2)."""
    listed = ", ".join(_signed(v) for _, v in study_figures(shifts, ref.STUDY_OVER_SCRATCH))
    return f"{listed} points" + ("" if str(top) == str(ref.TOP) else f" (at {ref.TOP} attempts)")


def _curve_count(rate: Rate | None) -> Count | None:
    """A curve point's target success as a count (None: not measured or its episodes unknown)."""
    if rate is None or not rate.episodes:
        return None
    return Count(round(rate.success_rate * rate.episodes), rate.episodes)


def stop_within(best: CriterionChoice, chosen: CriterionChoice, margin: float = 0.05) -> tuple[bool | None, str]:
    """Whether a choice lands within ``margin`` of the best point (None: its interval cannot tell), in words."""
    if chosen.step == best.step:
        return True, "the best point"
    b, c = _curve_count(best.target), _curve_count(chosen.target)
    if b is None or c is None:
        return None, f"{100 * (chosen.target_regret or 0.0):.0f} points below (scenes unknown: not resolvable)"
    d, lo, hi = diff_interval(b, c)
    text = f"{100 * d:.0f} [{100 * lo:+.0f}, {100 * hi:+.0f}] points below"
    if hi <= margin + 1e-12:
        return True, f"{text}: within {100 * margin:.0f} points"
    if lo > margin + 1e-12:
        return False, f"{text}: more than {100 * margin:.0f} points below"
    return None, f"{text}: not resolvable at {min(b.episodes, c.episodes)} scenes per point"


def early_stop_finding(records: Mapping[str, Any]) -> tuple[bool | None, str]:
    """(e) on our curve: does an offline criterion resolvably land within 5 points of the best point?"""
    choices = early_stop_choices(records)
    best = choices.get("best")
    if best is None or best.target is None:
        return None, "-"
    parts, verdicts = [], []
    for crit in [c for c in choices if c in OFFLINE_CRITERIA]:
        ch = choices[crit]
        if ch is None or ch.target is None:
            parts.append(f"{crit}: no choice")
            continue
        within, words = stop_within(best, ch)
        verdicts.append(within)
        parts.append(f"{crit}: step {ch.step}, {ch.target.percent()}, {words}")
    scenes = best.target.episodes or records["plan"]["early_stop"]["eval_episodes"]
    ours = f"best point step {best.step}, {best.target.percent()} ({scenes} scenes per point); " + "; ".join(parts)
    if not verdicts:
        return None, ours
    if any(verdicts):
        return True, ours
    if all(v is False for v in verdicts):
        return False, ours
    return None, ours + f"; the differences cannot be resolved at {scenes} scenes per point"


def findings_table(items: Sequence[Finding]) -> str:
    lines = ["| finding | verdict | ours (95% intervals) | study |", "|---|---|---|---|"]
    for f in items:
        lines.append(f"| ({f.key}) {f.claim} | **{f.verdict}** | {f.ours} | {f.study} |")
    return "\n".join(lines)


# --- plots ----------------------------------------------------------------------------------------------------------


def plot_tiers(records: Mapping[str, Any], path: Path) -> Path:
    """Success against target episodes per shift (ours solid with 95% intervals, the study's dotted)."""
    tiers = records["plan"]["finetune"]["tiers"]
    fig, ax = _subplots(figsize=(7.5, 4.5))
    for i, (shift, row) in enumerate(records["finetune"].items()):
        colour = f"C{i % 10}"
        pts = [(k, pooled(row["tiers"][str(k)])) for k in tiers]
        pts = [(k, c) for k, c in pts if c is not None]
        b0 = count(records["base_policy"].get(shift))
        if b0 is not None:
            pts = [(0, b0), *pts]
        if pts:
            x = [k for k, _ in pts]
            y = [100 * c.rate for _, c in pts]
            cis = [rate_interval(c) for _, c in pts]
            err = [
                [max(0.0, 100 * (c.rate - ci[0])) for (_, c), ci in zip(pts, cis)],
                [max(0.0, 100 * (ci[1] - c.rate)) for (_, c), ci in zip(pts, cis)],
            ]
            ax.errorbar(x, y, yerr=err, fmt="o-", color=colour, capsize=3, ms=4, label=_pretty(shift))
        study = ref.FINETUNE.get(ref.study_shift(shift))
        if study is not None:
            ks = [k for k in ref.TIERS if k <= max(tiers)]
            ax.plot([0, *ks], [study["base"], *[study[k] for k in ks]], ":", color=colour, alpha=0.6)
    ax.set_xscale("symlog", linthresh=max(1, min(tiers)))
    ax.set_xticks([0, *tiers], ["base", *[str(k) for k in tiers]])
    ax.set_ylim(-2, 102)
    ax.set_xlabel("target episodes in the fine-tuning data")
    ax.set_ylabel("success on the shift (%, 95% CI)")
    ax.set_title("Fine-tuning by data size (solid: ours; dotted: the study, real robot)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, path)


def plot_curves(records: Mapping[str, Any], path: Path) -> Path:
    """Target and base-task success over gradient steps per method: seeds thin, pooled mean with 95% band."""
    fig, axes = _subplots(1, 2, figsize=(11, 4.2), sharey=True)
    for ax, which, title in (
        (axes[0], "target", f"target: {_pretty(records['plan']['curves']['shift'])}"),
        (axes[1], "base", "base task"),
    ):
        for i, (method, by_seed) in enumerate(records["curves"].items()):
            colour = f"C{i % 10}"
            for rows in by_seed.values():
                seed_pts = mean_curve({"_": rows}, which)
                if seed_pts:
                    ax.plot(
                        [s for s, _ in seed_pts], [100 * c.rate for _, c in seed_pts], color=colour, alpha=0.25, lw=0.8
                    )
            pts = mean_curve(by_seed, which)
            if pts:
                x = [s for s, _ in pts]
                ax.plot(x, [100 * c.rate for _, c in pts], "o-", color=colour, ms=3, label=method)
                ax.fill_between(
                    x, [100 * c.ci[0] for _, c in pts], [100 * c.ci[1] for _, c in pts], color=colour, alpha=0.15
                )
        ax.set_title(title)
        ax.set_xlabel("gradient steps")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("success (%, seeds' mean; 95% CI over scenes)")
    axes[0].set_ylim(-2, 102)
    axes[0].legend(fontsize=8)
    return _save(fig, path)


def plot_online(records: Mapping[str, Any], path: Path) -> Path:
    """Figs. 5.10 and 5.11: target success against the grasps collected, per run, with 95% bands; the base policy's
    base-task success as a line."""
    o, runs = records["plan"]["online"], records["online"]
    panels = [
        (
            "Fig. 5.10: round 1's method",
            [r for r in runs.values() if r["ratio"] == o["ratio"] and r["method"] in o["methods"]],
        ),
        (
            "Fig. 5.11: target share, all parameters",
            [r for r in runs.values() if r["method"] == "ft" and r["ratio"] in o["ratios"]],
        ),
    ]
    panels = [(t, rs) for t, rs in panels if rs]
    fig, axes = _subplots(1, len(panels), figsize=(5.5 * len(panels), 4.2), sharey=True, squeeze=False)
    base = count(records["base_policy"].get("base"))
    for ax, (title, rs) in zip(axes[0], panels):
        for i, r in enumerate(sorted(rs, key=lambda r: (r["method"], r["ratio"]))):
            pts = [(g, c) for g, x in zip(r["grasps"], r["success"]) if (c := count(x)) is not None]
            if not pts:
                continue
            x = [g for g, _ in pts]
            label = r["method"] if title.startswith("Fig. 5.10") else f"{100 * r['ratio']:g}% target"
            ax.plot(x, [100 * c.rate for _, c in pts], "o-", color=f"C{i % 10}", ms=3, label=label)
            ax.fill_between(
                x, [100 * c.ci[0] for _, c in pts], [100 * c.ci[1] for _, c in pts], color=f"C{i % 10}", alpha=0.15
            )
        if base is not None:
            ax.axhline(100 * base.rate, color="k", ls="--", lw=1, label="base policy, base task")
        ax.set_title(f"{title}\n{_pretty(o['shift'])}")
        ax.set_xlabel("grasps collected online")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    axes[0][0].set_ylabel("success (%, 95% CI)")
    axes[0][0].set_ylim(-2, 102)
    return _save(fig, path)


def plot_weight_change(records: Mapping[str, Any], path: Path) -> Path:
    """Fig. 5.8: per layer (trunk to head), each shift's normalised cosine distance as a bar; 1 is the base task."""
    wc = records["weight_change"]
    shifts, layers = list(wc), list(next(iter(wc.values())))
    width = 0.8 / len(shifts)
    fig, ax = _subplots(figsize=(max(6.0, 0.6 * len(layers) + 2), 4.0))
    for i, shift in enumerate(shifts):
        xs = [j + (i - (len(shifts) - 1) / 2) * width for j in range(len(layers))]
        ax.bar(xs, [wc[shift][layer] for layer in layers], width, color=f"C{i % 10}", label=_pretty(shift))
    ax.axhline(1.0, color="k", lw=0.8, ls="--", label="fine-tune on the base task")
    ax.set_xticks(range(len(layers)), layers, rotation=40, ha="right", fontsize=8)
    ax.set_ylabel("cosine distance to the base / base task's")
    ax.set_title("Where the weights change (Fig. 5.8)")
    ax.legend(fontsize=7)
    ax.grid(axis="y", alpha=0.3)
    return _save(fig, path)


def plot_early_stop(records: Mapping[str, Any], path: Path) -> Path:
    from nsl.eval import plot_curve

    rows = _curve(records["early_stop"])
    choices = {k: v for k, v in early_stop_choices(records).items() if v is not None}
    return plot_curve(rows, path, choices=choices)


def _subplots(*grid: int, figsize: tuple[float, float], **kwargs: Any):
    """``(figure, axes)`` as ``pyplot.subplots`` gives them, on the figure's own Agg canvas: no pyplot state, and
    the backend of whoever imported nsl (a notebook's) stays as it was."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig, fig.subplots(*grid, **kwargs)


def _save(fig, path: Path) -> Path:
    import io

    from nsl.workspace import atomic_write_bytes

    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=110)
    atomic_write_bytes(Path(path), buf.getvalue())
    return Path(path)


# --- the document ---------------------------------------------------------------------------------------------------


def _lower_tier_seeds(f: Mapping[str, Any]) -> str:
    seeds = f.get("tier_seeds")
    return "" if seeds is None else f" (lower tiers: seeds {', '.join(map(str, seeds))})"


def _recipe_note(recipe: Mapping[str, Any] | None) -> str:
    """What the fine-tunes' checkpoints record beyond the plan: the rate, n-step, crop and conservative term."""
    if not recipe:
        return ""
    return (
        f" (learning rate {recipe['lr']:.3g}, {recipe['n_step']}-step returns, crop {recipe['augment_crop']}, "
        f"conservative term {recipe['conservative'] or 0:g})"
    )


def render(records: Mapping[str, Any], status: Mapping[str, Any] | None, figures: Mapping[str, str]) -> str:
    plan = records["plan"]
    st = status or {}
    units = st.get("units", {})
    seconds = sum(u.get("seconds") or 0 for u in units.values())
    done = sum(u.get("state") == "done" for u in units.values())
    c = plan["collect"]
    parts = [
        f"# Study `{records['study']}`",
        "",
        f"Plan: base `{plan['base']}`, shifts {', '.join(plan['shifts'])}; target data collected by the base "
        f"policy with **epsilon {c['epsilon']}** (random action probability per step), {c['episodes']} episodes "
        f"per shift (seed {c['seed']}); evaluations on {plan['eval']['episodes']} test-object scenes per cell "
        f"(scene seed {plan['eval']['seed']}, paired across checkpoints); base-task data: "
        f"{plan['base_data']['source']}"
        + ("" if plan["base_data"].get("verify", True) else " (**hashes not checked**: base_data.verify = false)")
        + ".",
        "",
        f"Units done: {done} of {len(units)}; time spent in units: {seconds / 60:.1f} minutes.",
        "Every 'study' figure is the real-robot result of the source study (Never Stop Learning, Tables 5.1-5.3); "
        "ours are "
        "simulation, with 95% Wilson intervals (differences: Newcombe intervals).",
        "",
        "## Findings",
        "",
        findings_table(findings(records)),
        "",
        "## Challenge table (Table 5.1)",
        "",
        challenge_table(records),
        "",
        "## Fine-tuning by data size (Table 5.2)",
        "",
        f"Fine-tune all parameters from the base, batches 50/50 base data and the first K target episodes, "
        f"25% of the base's learning rate and its n-step returns and crop, {plan['finetune']['steps']} steps"
        f"{_recipe_note(records.get('recipe'))}; training seeds "
        f"{', '.join(map(str, plan['finetune']['seeds']))} for the top tier and the baselines"
        f"{_lower_tier_seeds(plan['finetune'])}. With several seeds a cell is the seed mean ± its 95% t interval, "
        "then the pooled Wilson interval. Baselines: scratch is a random initialisation with the same data mix, "
        "scratch_target one on the target data alone, no_target the base fine-tuned on base data alone; "
        "supervised and supervised_frozen are a fresh head on supervised features (the trunk trained to classify "
        "the train objects from rendered frames, the project's analogue of the study's ImageNet column), the trunk "
        " ".join(["trained and frozen.", *filter(None, [features_note(records)]), "Success on the shift:"]),
        "",
        tiers_table(records),
        "",
    ]
    if "tiers" in figures:
        parts += [f"![fine-tuning by data size]({figures['tiers']})", ""]
    parts += ["The same checkpoints on the base task:", "", tiers_base_table(records), ""]
    if plan["finetune"].get("cross_shift"):
        parts += [
            "The top tier's fine-tunes on every shift (change against the base policy on that shift; seeds pooled):",
            "",
            cross_shift_table(records),
            "",
        ]
    if plan["finetune"].get("base_task"):
        parts += [
            "The base fine-tuned on base-task episodes it collected (Table 5.2's validation row), success on the "
            "base task:",
            "",
            base_task_tiers_table(records),
            "",
            "## Where the weights change (Fig. 5.8)",
            "",
            f"Cosine distance between the base's weights and its {plan['finetune']['tiers'][-1]}-episode fine-tune's, "
            "layer by layer (seed mean), divided by the same distance for the fine-tune on the base task: 1 is as "
            "much change as learning more of the base task itself, more is change the shift asks for. In the "
            "study every shift, even the morphological ones, changed the convolutional layers.",
            "",
            weight_change_table(records),
            "",
        ]
        if "weight_change" in figures:
            parts += [f"![where the weights change]({figures['weight_change']})", ""]
    if records.get("online"):
        o = plan["online"]
        parts += [
            "## Online fine-tuning (Figs. 5.10, 5.11)",
            "",
            f"The policy keeps collecting in {_pretty(o['shift'])}: each round, the last round's policy collects "
            f"{o['episodes']} grasps (round 1's are the base policy's own collection), and the next policy is "
            f"fine-tuned from it for {o['steps']} steps on every round's data so far, mixed with base data at the "
            "target share. Round 1 starts from the base with all parameters (ft) or a new head; later rounds "
            "continue with all parameters. Success on the shift's reporting scenes:",
            "",
            online_table(records),
            "",
        ]
        if "online" in figures:
            parts += [f"![online fine-tuning]({figures['online']})", ""]
    if plan.get("continual"):
        parts += [
            "## The continual sequence (Table 5.3)",
            "",
            f"{' -> '.join(['base', *plan['continual']['sequence']])}; each stage's policy collects "
            f"{plan['continual']['episodes']} episodes and fine-tunes from the previous stage, "
            f"{plan['continual']['steps']} steps. Single-step: the base fine-tuned on the base policy's "
            "episodes of that shift (same size and steps).",
            "",
            continual_table(records),
            "",
            "Performance matrix (rows: after each stage; columns: evaluated task):",
            "",
            matrix_table(records),
            "",
        ]
    if plan.get("curves"):
        cv = plan["curves"]
        parts += [
            "## Method curves (Figs. 5.4 and 5.9)",
            "",
            f"{_pretty(cv['shift'])}, {cv['episodes']} target episodes, evaluated every {cv['every']} steps on "
            f"{cv['eval_episodes']} scenes (target and base task), seeds {', '.join(map(str, cv['seeds']))}.",
            "",
            curves_table(records),
            "",
        ]
        if "curves" in figures:
            parts += [f"![method curves]({figures['curves']})", ""]
    if plan.get("early_stop"):
        es = plan["early_stop"]
        parts += [
            "## Overfitting and early stopping (Fig. 5.7)",
            "",
            f"{_pretty(es['shift'])}, {es['episodes']} target episodes ({int(es['holdout'] * 100)}% held out "
            f"for the offline criteria), {es['steps']} steps, evaluated every {es['every']} steps on "
            f"{es['eval_episodes']} scenes; each criterion replayed with patience {es['patience']}. The 'eval' "
            "criterion and the oracle see the same scenes. A criterion with no values on the curve made no "
            "choice.",
            "",
            early_stop_table(records),
            "",
        ]
        if "early_stop" in figures:
            parts += [f"![early stopping]({figures['early_stop']})", ""]
    return "\n".join(parts)
