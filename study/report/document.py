"""The report document, ``report.md``: the plan in words, the findings, each table and its plot."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from .cells import pretty
from .findings import features_note, findings
from .tables import (
    base_task_tiers_table,
    challenge_table,
    continual_matrix_table,
    continual_table,
    cross_shift_table,
    curves_table,
    early_stop_table,
    efficiency_table,
    findings_table,
    headline_table,
    online_table,
    plasticity_table,
    tiers_base_table,
    tiers_table,
    weight_change_table,
)

REPORT_FILE = "report.md"


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
    """report.md: the plan in words, the findings, then each experiment's tables and plots (``figures``: the plots'
    files by key: tiers, weight_change, online, curves, early_stop)."""
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
        *_findings(records),
        "",
        *_headline(records),
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
        + " ".join(["trained and frozen.", *filter(None, [features_note(records)]), "Success on the shift:"]),
        "",
        tiers_table(records),
        "",
    ]
    parts += _figure(figures, "tiers", "fine-tuning by data size")
    parts += _blocks("The same checkpoints on the base task:", tiers_base_table(records))
    if plan["finetune"].get("cross_shift"):
        parts += _blocks(
            "The top tier's fine-tunes on every shift (change against the base policy on that shift; seeds pooled):",
            cross_shift_table(records),
        )
    if plan["finetune"].get("base_task"):
        parts += _blocks(
            "The base fine-tuned on base-task episodes it collected (Table 5.2's validation row), success on the "
            "base task:",
            base_task_tiers_table(records),
            "## Where the weights change (Fig. 5.8)",
            f"Cosine distance between the base's weights and its {plan['finetune']['tiers'][-1]}-episode fine-tune's, "
            "layer by layer (seed mean), divided by the same distance for the fine-tune on the base task: 1 is as "
            "much change as learning more of the base task itself, more is change the shift asks for. In the "
            "study every shift, even the morphological ones, changed the convolutional layers.",
            weight_change_table(records),
        )
        parts += _figure(figures, "weight_change", "where the weights change")
    if records.get("online"):
        o = plan["online"]
        parts += _blocks(
            "## Online fine-tuning (Figs. 5.10, 5.11)",
            f"The policy keeps collecting in {pretty(o['shift'])}: each round, the last round's policy collects "
            f"{o['episodes']} grasps (round 1's are the base policy's own collection), and the next policy is "
            f"fine-tuned from it for {o['steps']} steps on every round's data so far, mixed with base data at the "
            "target share. Round 1 starts from the base with all parameters (ft) or a new head; later rounds "
            "continue with all parameters. Success on the shift's reporting scenes:",
            online_table(records),
        )
        parts += _figure(figures, "online", "online fine-tuning")
    if plan.get("continual"):
        parts += _blocks(
            "## The continual sequence (Table 5.3)",
            f"{' -> '.join(['base', *plan['continual']['sequence']])}; each stage's policy collects "
            f"{plan['continual']['episodes']} episodes and fine-tunes from the previous stage, "
            f"{plan['continual']['steps']} steps. Single-step: the base fine-tuned on the base policy's "
            "episodes of that shift (same size and steps).",
            continual_table(records),
            "Performance matrix (rows: after each stage; columns: evaluated task):",
            continual_matrix_table(records),
        )
    if plan.get("plasticity"):
        pl = plan["plasticity"]
        parts += _measured(
            "## Plasticity or data (finding (d))",
            f"{pretty(pl['shift'])}: fine-tunes of {pl['steps']} steps on {pl['episodes']} target episodes "
            f"(seeds {', '.join(map(str, pl['seeds']))}), from the base or from the continual sequence's stage "
            f"{pl['stage']} policy, on the episodes the base collected or those that policy collected. If the "
            "start explains the sequence's shortfall, the start's contrasts are negative whatever the data; if "
            "the data does, the data's are.",
            plasticity_table(records),
        )
    if plan.get("efficiency"):
        ef = plan["efficiency"]
        parts += _measured(
            "## Target data needed from scratch (finding (c))",
            f"At each tier of the base's episodes of the shift: FT from the base ({ef['ft_steps']} steps), and "
            f"scratch, from a random initialisation, with the recipe's base half and on the target data alone "
            f"({ef['scratch_steps']} steps), seeds {', '.join(map(str, ef['seeds']))}, on the reporting scenes. "
            f"Scratch reaches FT when the paired difference to FT at {ef['reference']} episodes has an interval "
            "that reaches 0. Scratch's selection curve says whether it had stopped improving.",
            efficiency_table(records),
        )
    if plan.get("curves"):
        cv = plan["curves"]
        parts += _blocks(
            "## Method curves (Figs. 5.4 and 5.9)",
            f"{pretty(cv['shift'])}, {cv['episodes']} target episodes, evaluated every {cv['every']} steps on "
            f"{cv['eval_episodes']} scenes (target and base task), seeds {', '.join(map(str, cv['seeds']))}.",
            curves_table(records),
        )
        parts += _figure(figures, "curves", "method curves")
    if plan.get("early_stop"):
        es = plan["early_stop"]
        first = (es.get("shifts") or [es["shift"]])[0]  # the first run's shift: the table's
        parts += _blocks(
            "## Overfitting and early stopping (Fig. 5.7)",
            f"{pretty(first)}, {es['episodes']} target episodes ({int(es['holdout'] * 100)}% held out "
            f"for the offline criteria), {es['steps']} steps, evaluated every {es['every']} steps on "
            f"{es['eval_episodes']} scenes; each criterion replayed with patience {es['patience']}. The 'eval' "
            "criterion and the oracle see the same scenes. A criterion with no values on the curve made no "
            "choice.",
            early_stop_table(records),
        )
        parts += _figure(figures, "early_stop", "early stopping")
    return "\n".join(parts)


def _findings(records: Mapping[str, Any]) -> list[str]:
    """The findings against the source, or why there are none: a plan whose shifts are none of the source's
    challenges (the engine as a shift, ``engine:pybullet``) has nothing of the source's to hold them to."""
    from nsl.study import reference as ref

    if not any(ref.study_shift(s) in ref.STUDY_DROPS for s in records["plan"]["shifts"]):
        return [
            "None of this plan's shifts is one of the source's challenges, so no finding of the source is tested "
            "here; the tables below give the measurements."
        ]
    return [findings_table(findings(records))]


def _headline(records: Mapping[str, Any]) -> list[str]:
    """The headline's section: the top tier's gain per shift and on average, with what each interval covers."""
    table = headline_table(records)
    if not table:
        return []
    f = records["plan"]["finetune"]
    colls = f.get("collections") or [records["plan"]["collect"]["seed"]]
    return _blocks(
        "## The headline: the gain of fine-tuning, with the variation that matters",
        f"The {f['tiers'][-1]}-episode fine-tunes: training seeds {', '.join(map(str, f['seeds']))} on each of "
        f"{len(colls)} independent target collection{'s' if len(colls) > 1 else ''} (collection seeds "
        f"{', '.join(map(str, colls))}), against the base policy on the same scenes. Each interval is the "
        "hierarchical paired bootstrap of `nsl.stats`: target collections, then training seeds within a collection, "
        "then scenes, each scene kept with its pair; the mean's is stratified by shift, with one scene draw shared "
        "by the shifts (scene i is the same objects and poses on every shift). The variance shares say where the "
        "uncertainty comes from. A level with one member is held fixed, and the interval says so.",
        table,
    )


def _blocks(*texts: str) -> list[str]:
    """Headings, paragraphs and tables of the document, each followed by a blank line."""
    return [line for text in texts for line in (text, "")]


def _measured(heading: str, intro: str, table: str) -> list[str]:
    """A section whose table is '' until something is measured: nothing until then."""
    return _blocks(heading, intro, table) if table else []


def _figure(figures: Mapping[str, str], key: str, alt: str) -> list[str]:
    """A plot's image, when it was drawn (``figures``: its file by key)."""
    return _blocks(f"![{alt}]({figures[key]})") if key in figures else []
