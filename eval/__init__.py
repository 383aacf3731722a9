"""Evaluation: success rates with intervals, paired comparisons, reports.

Public surface::

    wilson_interval, SuccessRate, EvalConfig, evaluate, run_eval_episodes, markdown_table
"""

from .success import EvalConfig, SuccessRate, evaluate, markdown_table, run_eval_episodes, wilson_interval

__all__ = ["EvalConfig", "SuccessRate", "evaluate", "markdown_table", "run_eval_episodes", "wilson_interval"]
