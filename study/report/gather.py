"""Reading a study's records: :func:`gather` collects the finished units' outputs (catalogued evaluations,
curve files, checkpoints) into ``records.json`` as plain counts, no derived numbers."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from nsl.eval import CurveRow

from ..plan import Plan
from ..units import (
    BASE_POLICY,
    FEATURES_POLICY,
    continual_tags,
    early_stop_runs,
    efficiency_runs,
    no_target_tag,
    online_runs,
    online_tag,
    plasticity_runs,
    top_tier_tags,
    train_tag,
)
from .cells import pooled

RECORDS_FILE = "records.json"


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
        *(r.shift for r in early_stop_runs(plan)),
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
                no_target_tag(f.steps, s) if m == "no_target" else train_tag(m, shift, top, f.steps, s)
                for s in f.seeds_of_baselines()
            ]
            row["baselines"][m] = [ev(t, shift) for t in tags]
            row["baselines_base"][m] = [ev(t, "base") for t in tags]
        extra = list(top_tier_tags(plan, shift).items())[1:]
        if extra:  # the top tier on the other target collections, by collection seed
            row["collections"] = {str(c): [ev(t, shift) for t in tags] for c, tags in extra}
            row["collections_base"] = {str(c): [ev(t, "base") for t in tags] for c, tags in extra}
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
    if plan.plasticity is not None:  # plasticity or data: each arm's runs on the shift and on the base task
        arms: dict[str, dict[str, list]] = {}
        for run in plasticity_runs(plan):
            a = arms.setdefault(run.arm, {"shift": [], "base": []})
            a["shift"].append(ev(run.tag, plan.plasticity.shift))
            a["base"].append(ev(run.tag, "base"))
        out["plasticity"] = arms
    if plan.efficiency is not None:  # target data needed from scratch: each run on its shift, scratch's curves
        eff: dict[str, dict[str, Any]] = {}
        for run in efficiency_runs(plan):
            m = eff.setdefault(run.shift, {}).setdefault(run.method, {"tiers": {}, "curves": {}})
            m["tiers"].setdefault(str(run.tier), []).append(ev(run.tag, run.shift))
            if run.method != "ft" and plan.efficiency.curve_every:
                m["curves"].setdefault(str(run.tier), []).append(_rows(read_curve_file(f"{study}-{run.tag}")))
        out["efficiency"] = eff
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
    runs = early_stop_runs(plan)
    if runs:
        out["early_stop"] = _rows(read_curve_file(f"{study}-{runs[0].tag}"))  # the first run: the report's table
        if len(runs) > 1:  # every run's curve (scripts/experiments/early_stopping.py reads them)
            out["early_stop_runs"] = {r.tag: _rows(read_curve_file(f"{study}-{r.tag}")) for r in runs}
    return out


def _rows(rows: Sequence[CurveRow] | None) -> list[dict] | None:
    return None if rows is None else [r.to_dict() for r in rows]


def online_key(method: str, ratio: float) -> str:
    """A run of the online records: ``ft@0.5``."""
    return f"{method}@{ratio:g}"


def features_accuracy(folder: Path | None) -> dict[str, Any] | None:
    """What the supervised features' training measured (held-out and training accuracy, chance and classes for a
    classifier; held-out and training pose errors against predicting the mean for the pose label; final loss), from
    its checkpoint at ``folder``; None until it exists or for imported weights (``--encoder``)."""
    from nsl.learners import read_config

    if folder is None:
        return None
    got = read_config(Path(folder)).get("data", {}).get("features")
    if not got:
        return None
    classes = ("classes", "heldout_accuracy", "train_accuracy", "chance")
    pose = ("pose_labels", "heldout_pose_error_ratio", "heldout_pose_error_ratios", "train_pose_error_ratio")
    out = {k: got[k] for k in (*classes, *pose, "final_loss") if k in got}
    return out if "final_loss" in out and (all(k in out for k in classes) or all(k in out for k in pose)) else None


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
