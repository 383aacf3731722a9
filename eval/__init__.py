"""Evaluation: success rates with intervals, paired comparisons, early stopping, continual metrics, reports.

Public surface (other folders and the CLI import these from ``nsl.eval`` only)::

    wilson_interval, SuccessRate, EvalConfig, evaluate, run_eval_episodes, markdown_table   # success rates
    evaluate_outcomes, success_rate_from_outcomes
    compare_paired, PairedComparison, mcnemar_exact, paired_difference_interval            # two policies
    welch_t_test, WelchResult
    EarlyStopping, EarlyStopConfig, EarlyStopMonitor, simulator_scorer, CRITERIA           # early stopping
    soft_opc, q_ranking_auc, td_error, offline_scores, held_out_episodes
    choose_steps, CriterionChoice, choices_table
    continual_metrics, ContinualMetrics, curve_auc                                         # continual learning
    Rate, CurveRow, PerformanceMatrix, TierRow, TierResults, read_curve, write_curve       # records
    write_report, ReportResult, tiers_table, matrix_table, plot_curve, plot_matrix, plot_tiers

``eval/`` may drive ``nsl.collectors`` with policies it is given; it never
imports ``nsl.learners`` (Q-values for the offline criteria come from the caller).
"""

from .continual import ContinualMetrics, continual_metrics, curve_auc
from .early_stopping import (CRITERIA, CriterionChoice, EarlyStopConfig, EarlyStopMonitor, EarlyStopping,
                             choices_table, choose_steps, held_out_episodes, load_early_stop, offline_scores,
                             q_ranking_auc, simulator_scorer, soft_opc, td_error)
from .paired import (PairedComparison, WelchResult, compare_paired, mcnemar_exact, paired_difference_interval,
                     welch_t_test)
from .plots import plot_curve, plot_matrix, plot_tiers
from .records import (CURVE_FILE, EARLY_STOP_FILE, MATRIX_FILE, REPORT_DIR, TIERS_FILE, CurveRow,
                      PerformanceMatrix, Rate, TierResults, TierRow, read_curve, read_eval_jsonl, write_curve)
from .report import ReportResult, matrix_table, tiers_table, write_report
from .success import (EvalConfig, SuccessRate, evaluate, evaluate_outcomes, markdown_table, run_eval_episodes,
                      success_rate_from_outcomes, wilson_interval)

__all__ = [
    "EvalConfig", "SuccessRate", "evaluate", "evaluate_outcomes", "markdown_table", "run_eval_episodes",
    "success_rate_from_outcomes", "wilson_interval",
    "PairedComparison", "WelchResult", "compare_paired", "mcnemar_exact", "paired_difference_interval",
    "welch_t_test",
    "CRITERIA", "CriterionChoice", "EarlyStopConfig", "EarlyStopMonitor", "EarlyStopping", "choices_table",
    "choose_steps", "held_out_episodes", "load_early_stop", "offline_scores", "q_ranking_auc", "simulator_scorer",
    "soft_opc", "td_error",
    "ContinualMetrics", "continual_metrics", "curve_auc",
    "CURVE_FILE", "EARLY_STOP_FILE", "MATRIX_FILE", "REPORT_DIR", "TIERS_FILE", "CurveRow", "PerformanceMatrix",
    "Rate", "TierResults", "TierRow", "read_curve", "read_eval_jsonl", "write_curve",
    "ReportResult", "matrix_table", "tiers_table", "write_report", "plot_curve", "plot_matrix", "plot_tiers",
]
