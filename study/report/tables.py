"""The report's Markdown tables, each a pure function of the records, the study's figures beside ours."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from nsl.eval import continual_metrics, matrix_table, pipe_table

from .. import reference as ref
from .cells import (
    continual_matrix,
    count,
    early_stop_choices,
    mean_curve,
    percent,
    points,
    pooled,
    pretty,
    seeds_cell,
)
from .findings import Finding, headline_gain, headline_text, shift_gain


def challenge_table(records: Mapping[str, Any]) -> str:
    """Table 5.1: the base policy on the base task and each shift, the drop in points, the study's figures."""
    bp = records["base_policy"]
    base = count(bp.get("base"))
    rows = [["base task", percent(base), "-", f"{ref.BASE_TASK}%", "-"]]
    for s in records["plan"]["shifts"]:
        c = count(bp.get(s))
        study = ref.CHALLENGE.get(ref.study_shift(s))
        rows.append(
            [
                pretty(s),
                percent(c),
                "-" if c is None or base is None else points(c, base),
                "-" if study is None else f"{study}%",
                "-" if study is None else f"{study - ref.BASE_TASK:+d}",
            ]
        )
    head = ["task", "base policy (ours)", "change, points (ours)", "study (real robot)", "study change"]
    return pipe_table(head, rows)


def _tier_columns(plan: Mapping[str, Any]) -> list[str]:
    """Table 5.2's columns after the base policy: each tier, then each baseline (at the top tier)."""
    tiers = plan["finetune"]["tiers"]
    return [*[str(k) for k in tiers], *[f"{m} ({tiers[-1]})" for m in plan["finetune"]["baselines"]]]


def _tier_cells(plan: Mapping[str, Any], row: Mapping[str, Any], on: str = "") -> list[str]:
    """A shift's fine-tunes in :func:`_tier_columns`, on the shift (``on=""``) or on the base task (``"_base"``)."""
    f = plan["finetune"]
    return [
        *[seeds_cell(row["tiers" + on][str(k)]) for k in f["tiers"]],
        *[seeds_cell(row["baselines" + on].get(m, [])) for m in f["baselines"]],
    ]


def tiers_table(records: Mapping[str, Any]) -> str:
    """Table 5.2: target success by tier, the baselines at the top tier; a 'study' row under each shift."""
    plan = records["plan"]
    rows = []
    for shift, row in records["finetune"].items():
        rows.append([pretty(shift), "ours", percent(count(records["base_policy"].get(shift))), *_tier_cells(plan, row)])
        study = ref.FINETUNE.get(ref.study_shift(shift))
        if study is not None:
            rows.append(
                [
                    "",
                    "study",
                    f"{study['base']}%",
                    *[f"{study[k]}%" if k in study else "-" for k in plan["finetune"]["tiers"]],
                    *[_study_baseline(study, m) for m in plan["finetune"]["baselines"]],
                ]
            )
    return pipe_table(["challenge", "", "base policy", *_tier_columns(plan)], rows)


def _study_baseline(study: Mapping[Any, int], baseline: str) -> str:
    """The study's figure for one of our baselines at its top tier (``-``: it has none)."""
    if baseline == "supervised_frozen":
        return f"{ref.SUPERVISED_FROZEN}%"
    key = ref.BASELINE_KEYS.get(baseline, baseline)
    return f"{study[key]}%" if key in study else "-"


def tiers_base_table(records: Mapping[str, Any]) -> str:
    """The same fine-tuned checkpoints on the base task (forgetting); the study's base-task row only as a note."""
    plan = records["plan"]
    base = percent(count(records["base_policy"].get("base")))
    rows = [[pretty(shift), base, *_tier_cells(plan, row, "_base")] for shift, row in records["finetune"].items()]
    return "\n".join(
        [pipe_table(["fine-tuned for", "base policy", *_tier_columns(plan)], rows), "", study_base_row_note()]
    )


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


def weight_change_table(records: Mapping[str, Any]) -> str:
    """Fig. 5.8 as a table: rows are layers, columns the shifts."""
    wc = records.get("weight_change")
    if not wc:
        return "(no weight changes yet: they need every top-tier fine-tune and the base-task fine-tune)"
    shifts = list(wc)
    layers = list(next(iter(wc.values())))
    return pipe_table(
        ["layer", *map(pretty, shifts)], [[layer, *[f"{wc[s][layer]:.2f}" for s in shifts]] for layer in layers]
    )


def base_task_tiers_table(records: Mapping[str, Any]) -> str:
    """Table 5.2's base-task row: the base fine-tuned on base-task episodes it collected, beside the study's."""
    bt = records.get("base_task")
    if not bt:
        return "(no base-task fine-tunes: set finetune.base_task = true)"
    tiers = list(bt)
    study = ref.FINETUNE["base"]
    rows = [
        ["ours", percent(count(records["base_policy"].get("base"))), *[seeds_cell(bt[t]) for t in tiers]],
        ["study", f"{study['base']}%", *[f"{study[int(t)]}%" if int(t) in study else "-" for t in tiers]],
    ]
    return pipe_table(["", "base policy", *tiers], rows)


def continual_table(records: Mapping[str, Any]) -> str:
    """Table 5.3: each stage on its own task, vs the base policy, vs single-step fine-tuning; the study's numbers."""
    m = continual_matrix(records)
    if m is None:
        return "(no continual results yet)"
    c = records["continual"]
    cells = c["cells"]
    tasks = c["tasks"]
    rows = []
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
        rows.append(
            [
                pretty(task),
                own_cell or "-",
                "-" if own is None or base is None else points(own, base),
                single_cell or "-",
                "-" if own is None or single is None else points(own, single),
                final_cell or "-",
                f"{ref.CONTINUAL.get(study_task, '-')}%",
                _study_vs_single(study_task),
            ]
        )
    b0, bT = count(cells[0][0]), count(cells[T][0])
    if b0 is not None and bT is not None:
        rows.append(
            [
                "base task",
                f"{b0.pct()} (base policy)",
                "-",
                "-",
                "-",
                f"{bT.pct()} ({points(bT, b0)})",
                "no forgetting found",
                "-",
            ]
        )
    head = [
        "stage task",
        "continual (own stage)",
        "vs base policy",
        "single-step from base",
        "vs single",
        "final",
        "study: own stage, each on its own task (Fig. 5.5)",
        "study: vs its single (best Table 5.2 tier; 800 tier)",
    ]
    return pipe_table(head, rows)


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
    shifts = records["plan"]["shifts"]
    fine_tunes = {s: r["cross_shift"] for s, r in records["finetune"].items() if r.get("cross_shift")}
    if not fine_tunes:
        return "(no cross-shift evaluations: set finetune.cross_shift = true)"
    base = [count(records["base_policy"].get(s)) for s in shifts]
    rows = [["base policy", *map(percent, base)]]
    for shift, row in fine_tunes.items():
        cells = []
        for other, b in zip(shifts, base):
            c = pooled(row[other])
            cells.append("-" if c is None else c.pct() + ("" if b is None else f" ({points(c, b)})"))
        rows.append([pretty(shift), *cells])
    return pipe_table(["fine-tuned for (rows), evaluated on (columns)", *map(pretty, shifts)], rows)


def continual_matrix_table(records: Mapping[str, Any]) -> str:
    """The continual sequence's performance matrix (eval's table) and its averages by eval.continual's definitions."""
    m = continual_matrix(records)
    if m is None:
        return "(no continual results yet)"
    metrics = continual_metrics(m)
    return (
        f"{matrix_table(m, pretty=True)}\n\nAverage forgetting {_pts(metrics.average_forgetting)} points, backward "
        f"transfer {_pts(metrics.average_backward_transfer)} points, average final success "
        f"{_pct(metrics.average_final_success)} (eval.continual's definitions)."
    )


def _pts(v: float | None) -> str:
    return "-" if v is None else f"{100 * v:+.0f}"


def _pct(v: float | None) -> str:
    return "-" if v is None else f"{100 * v:.0f}%"


def curves_table(records: Mapping[str, Any]) -> str:
    """Figs. 5.4/5.9 in numbers: per method, target and base-task success at the first, best and last point."""
    curves = records.get("curves")
    if not curves:
        return "(no method curves yet)"
    rows = []
    for method, by_seed in curves.items():
        pts = mean_curve(by_seed, "target")
        basepts = mean_curve(by_seed, "base")
        study = ref.CURVES.get(method, "-")
        if not pts:
            rows.append([method, str(len(by_seed)), "-", "-", "-", "-", study])
            continue
        best = max(pts, key=lambda p: (p[1].rate, -p[0]))
        rows.append(
            [
                method,
                str(len(by_seed)),
                pts[0][1].pct(),
                f"{best[1].pct()} ({best[0]})",
                pts[-1][1].pct(),
                basepts[-1][1].pct() if basepts else "-",
                study,
            ]
        )
    head = [
        "method",
        "seeds",
        "target at step 0",
        "best target (step)",
        "target at last step",
        "base task at last step",
        "study (sim, Fig. 5.4)",
    ]
    return pipe_table(head, rows)


def early_stop_table(records: Mapping[str, Any]) -> str:
    """Fig. 5.7's choices: each criterion's step, success there, and its distance below the best point."""
    choices = early_stop_choices(records)
    if not choices:
        return "(no early-stopping curve yet)"
    best = choices.get("best")
    rows = []
    for name, c in choices.items():
        label = {"best": "best point (oracle)", "final": "last step (no stopping)"}.get(name, name)
        if c is None:
            rows.append([label, "no choice", "-", "-", "-"])
            continue
        regret = "-" if c.target_regret is None else f"{100 * c.target_regret:.0f}"
        rows.append(
            [
                label,
                str(c.step),
                "-" if c.target is None else c.target.percent(),
                "-" if c.base is None else c.base.percent(),
                regret if best is not None else "-",
            ]
        )
    return pipe_table(["criterion", "chosen step", "target success", "base task", "points below the best"], rows)


def online_table(records: Mapping[str, Any]) -> str:
    """Figs. 5.10/5.11 as a table: each run's success after each round (round 0: the base policy)."""
    runs = records["online"]
    grasps = next(iter(runs.values()))["grasps"]
    ratio = records["plan"]["online"]["ratio"]
    rows = [
        [run["method"], f"{100 * run['ratio']:g}%", *[percent(count(x)) for x in run["success"]]]
        for run in sorted(runs.values(), key=lambda r: (r["ratio"] != ratio, r["method"], r["ratio"]))
    ]
    return pipe_table(["round 1's method", "target share", *[f"{g:,} grasps" for g in grasps]], rows)


def findings_table(items: Sequence[Finding]) -> str:
    """The findings, one row each: the claim, its verdict, our numbers and the study's."""
    rows = [[f"({f.key}) {f.claim}", f"**{f.verdict}**", f.ours, f.study] for f in items]
    return pipe_table(["finding", "verdict", "ours (95% intervals)", "study"], rows)


def headline_table(records: Mapping[str, Any]) -> str:
    """The top tier's gain on each shift and their mean, each with its hierarchical interval (over target
    collections, training seeds and scenes, each scene paired with the base) and the variance shares.  A shift
    whose runs are not all measured with per-scene outcomes has a row saying so, and the mean waits for every
    shift; empty when no shift is measured."""
    top = str(records["plan"]["finetune"]["tiers"][-1])
    rows, measured = [], 0
    for shift in records["finetune"]:
        g, b0 = shift_gain(records, shift), count(records["base_policy"].get(shift))
        if g is None or b0 is None:
            rows.append([pretty(shift), "-" if b0 is None else f"{100 * b0.rate:.1f}%", "-", "not measured yet", "-"])
            continue
        measured += 1
        shares = ", ".join(f"{100 * g.shares[lvl]:.0f}%" for lvl in ("collections", "seeds", "scenes"))
        rows.append(
            [
                pretty(shift),
                f"{100 * b0.rate:.1f}%",
                f"{100 * (b0.rate + g.mean):.1f}%",
                f"{100 * g.mean:+.1f} [{100 * g.low:+.1f}, {100 * g.high:+.1f}] ({g.covers()})",
                shares,
            ]
        )
    if not measured:
        return ""
    head = headline_gain(records)
    mean = f"**{headline_text(head)}**" if head is not None else f"waits for every shift ({measured} of {len(rows)})"
    rows.append(["**mean over shifts**", "", "", mean, ""])
    return pipe_table(
        [
            "shift",
            "base policy",
            f"{top}-episode fine-tunes (mean)",
            "gain, points [95%]",
            "variance: colls, seeds, scenes",
        ],
        rows,
    )


def _rate(r: Any) -> str:
    return f"{100 * r.mean:.1f}% [{100 * r.low:.1f}, {100 * r.high:.1f}]"


def plasticity_table(records: Mapping[str, Any]) -> str:
    """Plasticity or data: each arm's success on the shift and the base task (seed means with their hierarchical
    intervals over seeds and scenes), then the contrasts that separate the two causes, paired on the scenes:
    the start's effect with each data (base start - stage start), the data's effect with each start (the stage's
    episodes - the base's), and shrink and perturb against the stage's policy fine-tuned as it is; '' until an arm
    is measured."""
    from nsl.stats import hierarchical_difference, hierarchical_rate

    arms = records.get("plasticity") or {}
    pl = records["plan"]["plasticity"]
    stage = f"stage {pl['stage']}"

    def outcomes(arm: str, task: str) -> Any:
        return _outcomes((arms.get(arm) or {}).get(task))

    names = {
        "base/base": ("the base", "the base's"),
        "base/stage": ("the base", f"the {stage} policy's"),
        "stage/base": (f"the {stage} policy", "the base's"),
        "stage/stage": (f"the {stage} policy", f"the {stage} policy's"),
        "stage-sp/base": (f"the {stage} policy, shrunk and perturbed {tuple(pl['shrink_perturb'])}", "the base's"),
    }
    rows = []
    for arm, (start, data) in names.items():
        if arm not in arms:
            continue
        cells = ["-" if (o := outcomes(arm, t)) is None else _rate(hierarchical_rate(o)) for t in ("shift", "base")]
        rows.append([start, data, *cells])
    if not any(c != "-" for r in rows for c in r[2:]):
        return ""
    contrasts = [
        ("start: the base - the stage policy, on the base's episodes", "base/base", "stage/base"),
        (f"start: the base - the stage policy, on the {stage} policy's episodes", "base/stage", "stage/stage"),
        (f"data: the {stage} policy's - the base's episodes, from the base", "base/stage", "base/base"),
        (f"data: the {stage} policy's - the base's episodes, from the stage policy", "stage/stage", "stage/base"),
        ("shrink and perturb - the stage policy as it is, on the base's episodes", "stage-sp/base", "stage/base"),
    ]
    lines = [
        pipe_table(["start", "target episodes", "success on the shift [95%]", "base task [95%]"], rows),
        "",
    ]
    crows = []
    for label, a, b in contrasts:
        x, y = outcomes(a, "shift"), outcomes(b, "shift")
        if x is not None and y is not None:
            crows.append([label, hierarchical_difference(x, y).points()])
    if crows:
        lines.append(pipe_table(["contrast, on the shift", "points [95%, seeds and scenes, paired]"], crows))
    return "\n".join(lines)


def efficiency_match(records: Mapping[str, Any], shift: str, method: str) -> dict[str, Any] | None:
    """The smallest tier at which ``method``'s interval reaches FT's at the reference tier: the paired difference
    (method - FT@reference, seeds and scenes) has an upper end at or above 0.  ``tier`` None: no measured tier
    reaches it.  None until FT's reference cell is measured."""
    from nsl.stats import hierarchical_difference

    ef = records["plan"]["efficiency"]
    cells = ((records.get("efficiency") or {}).get(shift) or {}).get
    ft = _outcomes(((cells("ft") or {}).get("tiers") or {}).get(str(ef["reference"])))
    if ft is None:
        return None
    for tier in ef["tiers"]:
        got = _outcomes(((cells(method) or {}).get("tiers") or {}).get(str(tier)))
        if got is None:
            continue
        d = hierarchical_difference(got, ft)
        if d.high >= 0:
            return {"tier": tier, "difference": d.points(), "ratio": tier / ef["reference"]}
    return {"tier": None, "difference": None, "ratio": None}


def _outcomes(cells: Sequence[Any] | None) -> Any:
    """(1 collection, seeds, scenes) outcomes of a cell's seeds, or None while any is unmeasured."""
    if not cells or any(c is None or not c.get("outcomes") for c in cells):
        return None
    return [[[int(x) for x in c["outcomes"]] for c in cells]]


def efficiency_table(records: Mapping[str, Any]) -> str:
    """Target data needed from scratch: success on the shift at every tier (seed means, hierarchical intervals over
    seeds and scenes), scratch's selection curve at its last step against its best (converged or not), and the
    smallest tier at which each scratch method reaches FT at the reference tier; '' until a cell is measured."""
    from nsl.stats import hierarchical_rate

    ef = records["plan"]["efficiency"]
    data = records.get("efficiency") or {}
    names = {"ft": "FT", "scratch": "scratch (base half)", "scratch_target": "scratch (target only)"}
    lines: list[str] = []
    for shift, methods in data.items():
        rows = []
        for tier in ef["tiers"]:
            row = [str(tier)]
            for m in ef["methods"]:
                o = _outcomes(((methods.get(m) or {}).get("tiers") or {}).get(str(tier)))
                row.append("-" if o is None else _rate(hierarchical_rate(o)))
            rows.append(row)
        if not any(c != "-" for r in rows for c in r[1:]):
            continue
        lines += [f"**{shift}**", "", pipe_table(["target episodes", *(names[m] for m in ef["methods"])], rows), ""]
        crows = []
        for m in ef["methods"]:
            for tier, curves in ((methods.get(m) or {}).get("curves") or {}).items():
                done = [c for c in curves if c]
                if not done:
                    continue
                best = [max(c, key=lambda r: (r["target_success"] or 0.0, -r["step"])) for c in done]
                gap = [
                    100 * ((c[-1]["target_success"] or 0.0) - (b["target_success"] or 0.0)) for c, b in zip(done, best)
                ]
                steps = " ".join(str(b["step"]) for b in best)
                crows.append([names[m], tier, steps, f"{sum(gap) / len(gap):+.1f}"])
        if crows:
            lines += [
                pipe_table(["method", "tier", "best step on selection scenes, by seed", "last - best (points)"], crows),
                "",
            ]
        for m in ef["methods"]:
            if m == "ft":
                continue
            got = efficiency_match(records, shift, m)
            if got is None:
                continue
            if got["tier"] is None:
                lines.append(f"- {names[m]} does not reach FT at {ef['reference']} episodes by {ef['tiers'][-1]}.")
            else:
                lines.append(
                    f"- {names[m]} reaches FT at {ef['reference']} episodes with {got['tier']} "
                    f"({got['difference']} points against it): {got['ratio']:g}x FT's target data; FT needs "
                    f"{100 / got['ratio']:.0f}% of it (the source: 0.2% of scratch's)."
                )
        lines.append("")
    return "\n".join(lines).strip()
