"""The study's report: tables beside the source study's figures, plots, and findings (a)-(j) with intervals.

Two steps.  :func:`gather` reads the finished units' outputs (catalogued
evaluations, curve files) into ``records.json``: plain counts, no derived
numbers.  Everything else is a pure function of those records (and so can be
tested on hand-made ones): the tables, the plots and :func:`findings`.  One
job a module:

    gather.py     the records: gather, and the weight changes and features' accuracy it reads
    cells.py      a cell's count, seeds pooled, its 95% intervals (all from ``nsl.stats``)
    findings.py   Finding, findings (a)-(j) and their verdicts, the headline, the study's figures for each
    tables.py     the Markdown tables (on eval's ``pipe_table`` and ``matrix_table``)
    plots.py      the PNG plots (on eval's ``draw_tiers``, ``new_figure`` and ``save_png``)
    document.py   render: report.md from all of the above
"""

from .cells import Count, count, diff_interval, mean_curve, pooled, rate_interval, seed_mean, seeds_cell
from .document import REPORT_FILE, render
from .findings import Finding, findings, headline_gain, mean_gain_over_seeds, shift_gain
from .gather import RECORDS_FILE, gather
from .plots import plot_curves, plot_early_stop, plot_online, plot_tiers, plot_weight_change
from .tables import (
    challenge_table,
    continual_table,
    cross_shift_table,
    early_stop_table,
    efficiency_table,
    online_table,
    plasticity_table,
    tiers_base_table,
    tiers_table,
    weight_change_table,
)

__all__ = [
    "RECORDS_FILE",
    "REPORT_FILE",
    "Count",
    "Finding",
    "challenge_table",
    "continual_table",
    "count",
    "cross_shift_table",
    "diff_interval",
    "early_stop_table",
    "findings",
    "gather",
    "headline_gain",
    "mean_curve",
    "mean_gain_over_seeds",
    "online_table",
    "efficiency_table",
    "plasticity_table",
    "plot_curves",
    "plot_early_stop",
    "plot_online",
    "plot_tiers",
    "plot_weight_change",
    "pooled",
    "rate_interval",
    "render",
    "seed_mean",
    "seeds_cell",
    "shift_gain",
    "tiers_base_table",
    "tiers_table",
    "weight_change_table",
]
