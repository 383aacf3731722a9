"""Evaluation: success rates with intervals, paired comparisons, early stopping, continual metrics, reports.

Public surface (other folders and the CLI import these from ``nsl.eval`` only)::

    wilson_interval, SuccessRate, markdown_table, success_rate_from_outcomes               # statistics
    EvalConfig, evaluate, run_eval_episodes, evaluate_outcomes                              # in the simulator
    compare_paired, PairedComparison, mcnemar_exact, paired_difference_interval            # two policies
    EarlyStopping, EarlyStopConfig, EarlyStopMonitor, simulator_scorer, CRITERIA           # early stopping
    soft_opc, q_ranking_auc, td_error, offline_scores, held_out_episodes
    choose_steps, CriterionChoice, choices_table
    continual_metrics, ContinualMetrics, curve_auc                                         # continual learning
    Rate, CurveRow, PerformanceMatrix, TierRow, TierResults, read_curve, write_curve       # records
    write_report, ReportResult, tiers_table, matrix_table, plot_curve, plot_matrix, plot_tiers
    pipe_table, draw_tiers, new_figure, save_png                                           # pieces of reports

Each name is loaded from its module on first use (PEP 562), so the statistics
and records import no simulator: ``from nsl.eval import wilson_interval``
loads neither MuJoCo nor PyTorch; ``evaluate`` and the early-stopping monitor
load ``nsl.collectors`` when they are first asked for.

``eval/`` may drive ``nsl.collectors`` with policies it is given; it never
imports ``nsl.learners`` (Q-values for the offline criteria come from the caller).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from nsl.lazy import lazy_exports

_EXPORTS = {
    "stats": ("SuccessRate", "markdown_table", "success_rate_from_outcomes", "wilson_interval"),
    "config": ("CRITERIA", "EarlyStopConfig", "EarlyStopping", "EvalConfig"),
    "success": ("evaluate", "evaluate_outcomes", "run_eval_episodes"),
    "paired": ("PairedComparison", "compare_paired", "mcnemar_exact", "paired_difference_interval"),
    "early_stopping": (
        "CriterionChoice",
        "EarlyStopMonitor",
        "choices_table",
        "choose_steps",
        "held_out_episodes",
        "load_early_stop",
        "offline_scores",
        "q_ranking_auc",
        "simulator_scorer",
        "soft_opc",
        "td_error",
    ),
    "continual": ("ContinualMetrics", "continual_metrics", "curve_auc"),
    "records": (
        "CURVE_FILE",
        "EARLY_STOP_FILE",
        "MATRIX_FILE",
        "REPORT_DIR",
        "TIERS_FILE",
        "CurveRow",
        "PerformanceMatrix",
        "Rate",
        "TierResults",
        "TierRow",
        "read_curve",
        "read_eval_jsonl",
        "write_curve",
    ),
    "report": ("ReportResult", "matrix_table", "pipe_table", "tiers_table", "write_report"),
    "plots": ("draw_tiers", "new_figure", "plot_curve", "plot_matrix", "plot_tiers", "save_png"),
}
__all__, __getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())


if TYPE_CHECKING:  # static analysers see the eager imports
    from .config import CRITERIA, EarlyStopConfig, EarlyStopping, EvalConfig  # noqa: F401
    from .continual import ContinualMetrics, continual_metrics, curve_auc  # noqa: F401
    from .early_stopping import (  # noqa: F401
        CriterionChoice,
        EarlyStopMonitor,
        choices_table,
        choose_steps,
        held_out_episodes,
        load_early_stop,
        offline_scores,
        q_ranking_auc,
        simulator_scorer,
        soft_opc,
        td_error,
    )
    from .paired import PairedComparison, compare_paired, mcnemar_exact, paired_difference_interval  # noqa: F401
    from .plots import draw_tiers, new_figure, plot_curve, plot_matrix, plot_tiers, save_png  # noqa: F401
    from .records import (  # noqa: F401
        CURVE_FILE,
        EARLY_STOP_FILE,
        MATRIX_FILE,
        REPORT_DIR,
        TIERS_FILE,
        CurveRow,
        PerformanceMatrix,
        Rate,
        TierResults,
        TierRow,
        read_curve,
        read_eval_jsonl,
        write_curve,
    )
    from .report import ReportResult, matrix_table, pipe_table, tiers_table, write_report  # noqa: F401
    from .stats import SuccessRate, markdown_table, success_rate_from_outcomes, wilson_interval  # noqa: F401
    from .success import evaluate, evaluate_outcomes, run_eval_episodes  # noqa: F401
