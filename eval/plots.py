"""Figures for papers: early-stopping curves (Fig. 5.7), the performance matrix, sample efficiency (Fig. 5.6).

Every function draws on its own ``matplotlib.figure.Figure`` with the Agg
canvas (no pyplot state, no display needed) and writes a PNG through a
temporary file and a rename.
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Literal

import numpy as np

from nsl.workspace import atomic_write_bytes

from .early_stopping import CriterionChoice
from .records import CurveRow, PerformanceMatrix, TierResults

DPI = 150
# one colour and line style per criterion's vertical line
CHOICE_STYLE = {
    "best": ("black", "-"),
    "eval": ("tab:blue", "--"),
    "softopc": ("tab:red", ":"),
    "auc": ("tab:purple", "-."),
    "td": ("tab:brown", (0, (5, 2, 1, 2))),
    "final": ("grey", (0, (1, 3))),
}
OFFLINE_LABELS = {"softopc": "SoftOPC", "auc": "Q-ranking AUC", "td_error": "held-out TD error"}


def new_figure(width: float, height: float, dpi: float | None = DPI):
    """A ``matplotlib.figure.Figure`` of ``width`` x ``height`` inches on its own Agg canvas: no pyplot state, and
    the backend of whoever imported nsl (a notebook's) stays as it was (``dpi=None``: matplotlib's default)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=dpi)
    FigureCanvasAgg(fig)
    return fig


def save_png(fig, path: Path, dpi: float = DPI, tight: Literal["bbox", "layout"] = "bbox") -> Path:
    """Write ``fig`` as a PNG at ``path`` through a temporary file and a rename.  ``tight="bbox"`` crops the image
    to what is drawn; ``"layout"`` fits the axes into the figure first and keeps the figure's size."""
    buf = io.BytesIO()
    if tight == "layout":
        fig.tight_layout()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight" if tight == "bbox" else None)
    atomic_write_bytes(Path(path), buf.getvalue())
    return Path(path)


def _series(rows: Sequence[CurveRow], which: str):
    pts = [(r.step, getattr(r, which)) for r in rows if getattr(r, which) is not None]
    steps = np.array([s for s, _ in pts], dtype=float)
    mean = np.array([100 * rate.success_rate for _, rate in pts])
    cis = [rate.ci for _, rate in pts]
    lo = np.array([100 * (c[0] if c else rate.success_rate) for c, (_, rate) in zip(cis, pts)])
    hi = np.array([100 * (c[1] if c else rate.success_rate) for c, (_, rate) in zip(cis, pts)])
    return steps, mean, lo, hi


def _use_log_x(steps: np.ndarray) -> bool:
    pos = steps[steps > 0]
    return len(pos) > 1 and pos.max() / pos.min() >= 100


def plot_curve(
    rows: Sequence[CurveRow],
    path: Path,
    choices: Mapping[str, CriterionChoice] | None = None,
    title: str = "Offline fine-tuning",
    references: Mapping[str, float] | None = None,
    target_name: str = "target shift",
) -> Path:
    """Success vs gradient steps with 95% bands; the base task shows forgetting; offline criteria below.

    Vertical lines mark the step each criterion chose; a dotted horizontal line
    marks the step-0 (base policy) target success and each entry of ``references``.
    """
    rows = sorted(rows, key=lambda r: r.step)
    offline = [c for c in ("softopc", "auc", "td_error") if any(r.value(c) is not None for r in rows)]
    fig = new_figure(7.5, 4.2 + 1.5 * len(offline))
    axes = fig.subplots(
        1 + len(offline), 1, sharex=True, squeeze=False, gridspec_kw={"height_ratios": [3] + [1] * len(offline)}
    )[:, 0]
    ax = axes[0]
    steps_all = np.array([r.step for r in rows], dtype=float)
    for which, colour, label in (
        ("target", "tab:blue", f"fine-tuned policy on {target_name}"),
        ("base", "tab:green", "fine-tuned policy on base task"),
    ):
        steps, mean, lo, hi = _series(rows, which)
        if len(steps):
            ax.plot(steps, mean, "o-", color=colour, ms=3, lw=1.5, label=label)
            ax.fill_between(steps, lo, hi, color=colour, alpha=0.18, lw=0)
    first = rows[0] if rows else None
    if first is not None and first.step == 0 and first.target is not None:
        ax.axhline(
            100 * first.target.success_rate, color="goldenrod", ls=":", lw=1.5, label=f"base policy on {target_name}"
        )
    for i, (name, value) in enumerate((references or {}).items()):
        ax.axhline(100 * value, color=f"C{(i + 5) % 10}", ls=":", lw=1.5, label=name)
    for name, choice in (choices or {}).items():
        colour, style = CHOICE_STYLE.get(name, ("grey", "--"))
        label = {"best": "best evaluated (hindsight)", "final": "last step"}.get(name, f"{name} chooses")
        for a in axes:
            a.axvline(choice.step, color=colour, ls=style, lw=1.2, label=f"{label}: {choice.step}" if a is ax else None)
    ax.set_ylim(-2, 102)
    ax.set_ylabel("success rate (%, 95% CI)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    for a, column in zip(axes[1:], offline):
        pts = [(r.step, r.value(column)) for r in rows if r.value(column) is not None]
        a.plot([p[0] for p in pts], [p[1] for p in pts], "o-", ms=3, lw=1.2, color="tab:red")
        a.set_ylabel(OFFLINE_LABELS[column], fontsize=8)
        a.grid(alpha=0.3)
    if _use_log_x(steps_all):
        axes[0].set_xscale("symlog", linthresh=max(1.0, float(np.min(steps_all[steps_all > 0]))))
    axes[-1].set_xlabel("gradient steps")
    return save_png(fig, path)


def plot_matrix(matrix: PerformanceMatrix, path: Path, title: str = "Performance matrix") -> Path:
    """Heatmap of R[stage, task] in percent, the number written in each cell."""
    R = np.array([[np.nan if v is None else 100 * v for v in row] for row in matrix.success], dtype=float)
    n_rows, n_cols = R.shape
    fig = new_figure(1.2 + 1.15 * n_cols, 1.0 + 0.55 * n_rows)
    ax = fig.subplots()
    im = ax.imshow(np.ma.masked_invalid(R), cmap="viridis", vmin=0, vmax=100, aspect="auto")
    cbar = fig.colorbar(im, ax=ax, fraction=0.04, pad=0.02)
    cbar.set_label("success rate (%)")
    for i in range(n_rows):
        for j in range(n_cols):
            v = R[i, j]
            if np.isnan(v):
                ax.text(j, i, "-", ha="center", va="center", color="grey", fontsize=9)
                continue
            rate = matrix.rate(i, j)
            ci = rate.ci if rate is not None else None
            text = f"{v:.0f}" + (f"\n[{100 * ci[0]:.0f}-{100 * ci[1]:.0f}]" if ci else "")
            ax.text(
                j, i, text, ha="center", va="center", fontsize=8 if ci else 10, color="black" if v > 60 else "white"
            )
    ax.set_xticks(range(n_cols), [t.replace("_", " ") for t in matrix.tasks], rotation=30, ha="right", fontsize=8)
    ax.set_yticks(range(n_rows), [f"{i}: {s.replace('_', ' ')}" for i, s in enumerate(matrix.stages)], fontsize=8)
    ax.set_xlabel("evaluated on task")
    ax.set_ylabel("after training stage")
    ax.set_title(title)
    return save_png(fig, path)


def draw_tiers(
    ax,
    lines: Mapping[str, Sequence[tuple[float, float, tuple[float, float] | None]]],
    ticks: Sequence[int],
    *,
    bases: Mapping[str, float | None] | None = None,
    references: Mapping[str, Sequence[tuple[float, float]]] | None = None,
    dodge: float = 1.04,
) -> None:
    """Success against target attempts on ``ax``, one colour per shift (Fig. 5.6).

    ``lines[shift]`` holds ``(attempts, success, 95% interval or None)`` points, drawn with error bars, each
    line's x dodged by a factor of ``dodge`` so that the bars do not overlap; ``bases[shift]`` (the base
    policy's success) is a dashed line and ``references[shift]`` (``(attempts, success)``, e.g. a published
    study's figures) a dotted one, in the shift's colour.  The x axis is logarithmic with a tick at each of
    ``ticks``; a tick at 0 (the base policy as each line's first point) makes it linear up to the smallest
    tier (symlog), labelled "base".
    """
    for i, (name, pts) in enumerate(lines.items()):
        colour = f"C{i % 10}"
        if pts:
            x = np.array([k for k, _, _ in pts], dtype=float) * dodge ** (i - (len(lines) - 1) / 2)
            y = np.array([100 * v for _, v, _ in pts])
            err = np.array([[100 * (v - ci[0]), 100 * (ci[1] - v)] if ci else [0.0, 0.0] for _, v, ci in pts]).T.clip(
                min=0.0
            )  # 0% or 100%: rounding below 0
            ax.errorbar(x, y, yerr=err, fmt="o-", color=colour, capsize=3, ms=4, lw=1.5, label=name.replace("_", " "))
        base = (bases or {}).get(name)
        if base is not None:
            ax.axhline(100 * base, color=colour, ls="--", lw=1, alpha=0.7)
        reference = (references or {}).get(name)
        if reference:
            ax.plot([k for k, _ in reference], [100 * v for _, v in reference], ":", color=colour, alpha=0.6)
    if 0 in ticks:
        ax.set_xscale("symlog", linthresh=max(1, min((k for k in ticks if k > 0), default=1)))
    else:
        ax.set_xscale("log")
    if ticks:
        ax.set_xticks(ticks, ["base" if k == 0 else str(k) for k in ticks])
    ax.set_ylim(-2, 102)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def plot_tiers(
    tiers: TierResults, path: Path, title: str = "Sample efficiency", shifts: Sequence[str] | None = None
) -> Path:
    """Success vs number of target attempts (log x) with 95% intervals, one line per shift (Fig. 5.6).

    The base policy (no target data) of each shift is a dashed line in the same colour.
    """
    fig = new_figure(7.0, 4.5)
    ax = fig.subplots()
    rows = {name: tiers.rows[name] for name in (list(shifts) if shifts is not None else list(tiers.rows))}
    lines = {name: sorted((k, v) for k, v in (row.tiers or {}).items() if v is not None) for name, row in rows.items()}
    draw_tiers(
        ax,
        {name: [(k, v.success_rate, v.ci) for k, v in pts] for name, pts in lines.items()},
        tiers.tiers,
        bases={name: None if row.base is None else row.base.success_rate for name, row in rows.items()},
    )
    if tiers.tiers:
        ax.minorticks_off()
    ax.set_xlabel("target attempts in the fine-tuning dataset (log scale)")
    ax.set_ylabel("success rate (%, 95% CI)")
    ax.set_title(title + " (dashed: base policy)")
    return save_png(fig, path)
