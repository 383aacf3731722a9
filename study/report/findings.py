"""Findings (a)-(j): each claim of the study, our verdict on it with 95% intervals, and the study's figures."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from nsl.eval import CriterionChoice
from nsl.stats import (
    HierarchicalGain,
    compare_intervals,
    hierarchical_gain,
    hierarchical_mean_gain,
    mean_gain_of_rates,
    t_interval,
)

from .. import reference as ref
from .cells import continual_matrix, count, diff_interval, early_stop_choices, points, pooled, pretty, rate_count
from .gather import online_key

OFFLINE_CRITERIA = ("softopc", "auc", "td")


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


def top_tier_outcomes(records: Mapping[str, Any], shift: str):
    """The top tier's fine-tunes on ``shift`` and the base policy there, as 0/1 arrays on the same scenes:
    ``((collections, seeds, scenes), (scenes,))``, the plan's collection first.  None unless every run and the
    base recorded per-scene outcomes, every collection has the same seeds, and all met the same scenes."""
    import numpy as np

    row, b0 = records["finetune"][shift], count(records["base_policy"].get(shift))
    top = str(records["plan"]["finetune"]["tiers"][-1])
    groups = [row["tiers"][top], *(row.get("collections") or {}).values()]
    cells = [[count(d) for d in g] for g in groups]
    if b0 is None or b0.outcomes is None or not cells[0]:
        return None
    if any(len(g) != len(cells[0]) or any(c is None or c.outcomes is None for c in g) for g in cells):
        return None
    if any(len(c.outcomes) != len(b0.outcomes) for g in cells for c in g):  # type: ignore[union-attr]
        return None
    ft = np.array([[[ch == "1" for ch in c.outcomes] for c in g] for g in cells], dtype=np.int8)  # type: ignore
    return ft, np.array([ch == "1" for ch in b0.outcomes], dtype=np.int8)


def shift_gain(records: Mapping[str, Any], shift: str) -> HierarchicalGain | None:
    """The top tier's gain over the base policy on one shift, its hierarchical interval over target collections,
    training seeds and scenes (``nsl.stats.hierarchical_gain``); None without per-scene outcomes."""
    got = top_tier_outcomes(records, shift)
    return None if got is None else hierarchical_gain(*got)


def headline_gain(records: Mapping[str, Any]) -> HierarchicalGain | None:
    """The headline: the top tier's mean gain over the plan's shifts, with its hierarchical interval (stratified by
    shift; collections, then seeds, then scenes, each scene paired with the base) and its variance shares
    (``nsl.stats.hierarchical_mean_gain``).  None unless every shift has the same collections, seeds and scenes
    with per-scene outcomes."""
    import numpy as np

    got = [top_tier_outcomes(records, s) for s in records["finetune"]]
    if not got or any(g is None for g in got) or len({g[0].shape for g in got}) != 1:  # type: ignore[index]
        return None
    ft = np.stack([g[0] for g in got])  # type: ignore[index]
    base = np.stack([g[1] for g in got])  # type: ignore[index]
    return hierarchical_mean_gain(ft, base)


def headline_text(g: HierarchicalGain) -> str:
    """The headline in one line: the mean gain, its interval, what it covers and the variance shares."""
    shares = ", ".join(f"{lvl} {100 * g.shares[lvl]:.0f}%" for lvl in ("collections", "seeds", "scenes"))
    return (
        f"{100 * g.mean:+.1f} points [{100 * g.low:+.1f}, {100 * g.high:+.1f}] (95% hierarchical interval over "
        f"{g.covers()}; variance of the mean: {shares})"
    )


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
            "drops of " + "; ".join(f"{pretty(s)} {points(a, b)}" for s, (a, b) in measured.items())
            if measured
            else "-",
            study_drops(plan["shifts"]),
        )
    )
    # (b) fine-tuning on the top tier gains at least the study's +27 points on average; reaches base on 2 of 5
    top = str(plan["finetune"]["tiers"][-1])
    gains, reached, parts = [], [], []
    head = headline_gain(records)  # every collection, seed and scene, when the outcomes were recorded
    for shift, row in records["finetune"].items():
        ft, b0 = pooled(row["tiers"][top]), count(bp.get(shift))
        if ft is None or b0 is None:
            continue
        g = shift_gain(records, shift) if head is not None else None
        if g is not None:
            gains.append(g.mean)
            parts.append(f"{pretty(shift)} {100 * g.mean:+.1f} [{100 * g.low:+.1f}, {100 * g.high:+.1f}]")
            level = b0.rate + g.mean
        else:
            gains.append(ft.rate - b0.rate)
            parts.append(f"{pretty(shift)} {points(ft, b0)}")
            level = ft.rate
        if base is not None and level >= base.rate:
            reached.append(shift)
    n = len(records["finetune"])
    verdict_b = ""
    if len(gains) < n:
        holds_b = None
    else:
        if head is not None:
            ours_b, covers_b = (head.mean, head.low, head.high), f"hierarchical, over {head.covers()}"
        else:  # no per-scene outcomes: each shift's own interval, combined in quadrature
            shift_gains = [
                diff_interval(pooled(r["tiers"][top]), count(bp.get(s)))  # type: ignore[arg-type]
                for s, r in records["finetune"].items()
            ]
            ours_b, covers_b = mean_of_gains(shift_gains), "shifts combined in quadrature, one collection fixed"
        source_b = study_gain_interval(plan["shifts"])
        verdict_b = compare_intervals(ours_b, source_b)
        holds_b = {"holds": True, "fails": False}.get(verdict_b)
        verdict_b = (
            f"; against the study's binomial interval (N={ref.STUDY_N} per cell) "
            f"{100 * source_b[0]:+.1f} [{100 * source_b[1]:+.1f}, {100 * source_b[2]:+.1f}], ours "
            f"{100 * ours_b[0]:+.1f} [{100 * ours_b[1]:+.1f}, {100 * ours_b[2]:+.1f}] ({covers_b}): {verdict_b}"
        )
    out.append(
        Finding(
            "b",
            f"fine-tuning on {top} episodes gains at least as much as the study's (mean {ref.STUDY_MEAN_GAIN_800:+d} "
            f"points; reaches the base policy's base-task success on {len(ref.STUDY_REACHED_BASE)} of "
            f"{len(ref.CHALLENGE)} shifts)",
            holds_b,
            (
                (
                    f"mean {headline_text(head)}"
                    if head is not None and len(gains) == n
                    else f"mean {100 * sum(gains) / len(gains):+.0f} points{_over_seeds(records, top)}"
                )
                + f" ({'; '.join(parts)}); "
                "reaches the base policy's "
                f"base-task success on {len(reached)} of {n}"
                + (f" ({', '.join(map(pretty, reached))})" if reached else "")
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
        parts.append(f"{pretty(shift)} {points(ft, sc)}")
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
            f"not solved in the study ({pretty(ref.EARLY_STOP_SHIFT)}, {ref.EARLY_STOP_ATTEMPTS} attempts: "
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
                f"{pretty(s)} {m:.2f}x" for s, m in means.items()
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
            parts.append(f"{pretty(shift)} RL {ft.pct()} against " + ", ".join(cells))
    expected = len(records["finetune"]) * len(baselines)
    holds = None if len(lows) < expected else all(lo > 0 for lo in lows)
    study = ", ".join(
        f"{pretty(ref.study_shift(s))} {ref.FINETUNE[ref.study_shift(s)][ref.TOP]}% against "
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


def features_note(records: Mapping[str, Any]) -> str:
    """How well the supervised trunk learned its task (classes, pose or both), a sentence each ('' until measured)."""
    f = records.get("features")
    if not f:
        return ""
    parts = []
    if f.get("heldout_accuracy") is not None:
        parts.append(
            f"The supervised trunk classifies {100 * f['heldout_accuracy']:.1f}% of held-out frames of the "
            f"{f['classes']} train objects (chance {100 * f['chance']:.2f}%; {100 * f['train_accuracy']:.1f}% of its "
            f"training frames, final loss {f['final_loss']:.2f})."
        )
    if f.get("heldout_pose_error_ratio") is not None:
        per = ", ".join(f"{k} {v:.2f}" for k, v in zip(f["pose_labels"], f["heldout_pose_error_ratios"]))
        parts.append(
            f"The supervised trunk locates the object relative to the camera on held-out frames with "
            f"{f['heldout_pose_error_ratio']:.2f} of the squared error of predicting the mean ({per}; "
            f"{f['train_pose_error_ratio']:.2f} on its training frames; at most 0.5 counts as learned)."
        )
    return " ".join(parts)


def cross_shift_forgetting(records: Mapping[str, Any]) -> tuple[float, int] | None:
    """Mean change (fraction) of the top tier's fine-tunes on the shifts they were not trained on, and the pairs."""
    changes = []
    for shift, row in records["finetune"].items():
        for other, items in (row.get("cross_shift") or {}).items():
            c, b = pooled(items), count(records["base_policy"].get(other))
            if other != shift and c is not None and b is not None:
                changes.append(c.rate - b.rate)
    return (sum(changes) / len(changes), len(changes)) if changes else None


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
    listed = "; ".join(f"{pretty(ref.study_shift(s))} {'-' if v is None else v}" for s, v in figs)
    return f"drops of {listed} points" + (f" ({min(known)}-{max(known)})" if known else "")


def study_gains(shifts: Sequence[str]) -> str:
    """(b) in the study: the top tier's gain on each of the plan's shifts (Table 5.2), its mean, who reached 86%."""
    figs = study_figures(shifts, ref.STUDY_GAINS)
    known = [(s, v) for s, v in figs if v is not None]
    listed = "; ".join(f"{pretty(ref.study_shift(s))} {_signed(v)}" for s, v in figs)
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
        + (f" ({', '.join(pretty(ref.study_shift(s)) for s in reached)})" if reached else "")
        + ("" if every else f" ({len(ref.STUDY_REACHED_BASE)} of its {len(ref.CHALLENGE)})")
    )


def study_over_scratch(shifts: Sequence[str], top: str) -> str:
    """(c) in the study: fine-tuning minus scratch at its top tier on each of the plan's shifts (Table 5.2)."""
    listed = ", ".join(_signed(v) for _, v in study_figures(shifts, ref.STUDY_OVER_SCRATCH))
    return f"{listed} points" + ("" if str(top) == str(ref.TOP) else f" (at {ref.TOP} attempts)")


def stop_within(best: CriterionChoice, chosen: CriterionChoice, margin: float = 0.05) -> tuple[bool | None, str]:
    """Whether a choice lands within ``margin`` of the best point (None: its interval cannot tell), in words."""
    if chosen.step == best.step:
        return True, "the best point"
    b, c = rate_count(best.target), rate_count(chosen.target)
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
