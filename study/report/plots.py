"""The report's PNG plots, each drawn from the records on its own figure (no pyplot state)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from nsl.eval import draw_tiers, new_figure, plot_curve, save_png

from .. import reference as ref
from .cells import count, curve_rows, early_stop_choices, mean_curve, pooled, pretty, rate_interval

DPI = 110  # the plots' resolution; each is laid out to fill its figure


def plot_tiers(records: Mapping[str, Any], path: Path) -> Path:
    """Success against target episodes per shift (ours solid with 95% intervals, the study's dotted)."""
    tiers = records["plan"]["finetune"]["tiers"]
    fig, ax = _subplots(figsize=(7.5, 4.5))
    lines, study = {}, {}
    for shift, row in records["finetune"].items():
        pts = [(k, pooled(row["tiers"][str(k)])) for k in tiers]
        pts = [(k, c) for k, c in pts if c is not None]
        b0 = count(records["base_policy"].get(shift))
        if b0 is not None:
            pts = [(0, b0), *pts]
        lines[shift] = [(k, c.rate, rate_interval(c)) for k, c in pts]
        source = ref.FINETUNE.get(ref.study_shift(shift))
        if source is not None:
            ks = [k for k in ref.TIERS if k <= max(tiers)]
            study[shift] = [(0, source["base"] / 100), *[(k, source[k] / 100) for k in ks]]
    draw_tiers(ax, lines, [0, *tiers], references=study, dodge=1.0)
    ax.set_xlabel("target episodes in the fine-tuning data")
    ax.set_ylabel("success on the shift (%, 95% CI)")
    ax.set_title("Fine-tuning by data size (solid: ours; dotted: the study, real robot)")
    return save_png(fig, path, DPI, "layout")


def plot_curves(records: Mapping[str, Any], path: Path) -> Path:
    """Target and base-task success over gradient steps per method: seeds thin, pooled mean with 95% band."""
    fig, axes = _subplots(1, 2, figsize=(11, 4.2), sharey=True)
    for ax, which, title in (
        (axes[0], "target", f"target: {pretty(records['plan']['curves']['shift'])}"),
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
    return save_png(fig, path, DPI, "layout")


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
        ax.set_title(f"{title}\n{pretty(o['shift'])}")
        ax.set_xlabel("grasps collected online")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    axes[0][0].set_ylabel("success (%, 95% CI)")
    axes[0][0].set_ylim(-2, 102)
    return save_png(fig, path, DPI, "layout")


def plot_weight_change(records: Mapping[str, Any], path: Path) -> Path:
    """Fig. 5.8: per layer (trunk to head), each shift's normalised cosine distance as a bar; 1 is the base task."""
    wc = records["weight_change"]
    shifts, layers = list(wc), list(next(iter(wc.values())))
    width = 0.8 / len(shifts)
    fig, ax = _subplots(figsize=(max(6.0, 0.6 * len(layers) + 2), 4.0))
    for i, shift in enumerate(shifts):
        xs = [j + (i - (len(shifts) - 1) / 2) * width for j in range(len(layers))]
        ax.bar(xs, [wc[shift][layer] for layer in layers], width, color=f"C{i % 10}", label=pretty(shift))
    ax.axhline(1.0, color="k", lw=0.8, ls="--", label="fine-tune on the base task")
    ax.set_xticks(range(len(layers)), layers, rotation=40, ha="right", fontsize=8)
    ax.set_ylabel("cosine distance to the base / base task's")
    ax.set_title("Where the weights change (Fig. 5.8)")
    ax.legend(fontsize=7)
    ax.grid(axis="y", alpha=0.3)
    return save_png(fig, path, DPI, "layout")


def plot_early_stop(records: Mapping[str, Any], path: Path) -> Path:
    rows = curve_rows(records["early_stop"])
    choices = {k: v for k, v in early_stop_choices(records).items() if v is not None}
    return plot_curve(rows, path, choices=choices)


def _subplots(*grid: int, figsize: tuple[float, float], **kwargs: Any):
    """``(figure, axes)`` as ``pyplot.subplots`` gives them, on eval's figure (its own Agg canvas, no pyplot state)
    at matplotlib's default resolution."""
    fig = new_figure(*figsize, dpi=None)
    return fig, fig.subplots(*grid, **kwargs)
