"""Continual-learning metrics from a performance matrix (Continual World, Wolczyk et al. 2021).

``R[i, j]`` is the success on task ``j`` of the checkpoint after stage ``i``;
stage 0 is the initial checkpoint and ``t_j`` is the stage that trained task
``j`` (0 for the base task, which the initial checkpoint was trained on).
``T`` is the last stage in the matrix.  Per task ``j`` (None where undefined):

* own-stage success   ``R[t_j, j]``: right after training on j (Table 5.3's "continual" column);
* final success       ``R[T, j]``;  average final success = mean over all tasks of ``R[T, j]``;
* forgetting          ``max_{t_j <= i < T} R[i, j] - R[T, j]``: best success since its training, minus final
                      (the issue's definition; positive = forgotten; undefined for the task trained at T);
* forgetting_end      ``R[t_j, j] - R[T, j]``: Continual World's, from the end of its own training;
* backward transfer   ``R[T, j] - R[t_j, j]`` (GEM's BWT per task; averaged over tasks with t_j < T);
* forward transfer    ``R[t_j, j] - b_j`` against a reference ``b_j`` (success of training task j from
                      scratch, the same budget) -- the end-point version of Continual World's metric;
* forward transfer (AUC) ``(AUC_j - AUC_j^b) / (1 - AUC_j^b)`` when success curves during stage t_j
                      and of the from-scratch reference are given (AUC of success over the normalised
                      step range; Continual World's definition);
* zero-shot transfer  ``R[t_j - 1, j] - R[0, j]``: what the earlier stages did for j before it was trained;
* vs base             ``R[t_j, j] - R[0, j]`` (Table 5.3's "Base" column);
* vs single           ``R[t_j, j] - s_j`` with ``s_j`` single-step fine-tuning of the initial checkpoint on j
                      (Table 5.3's "Single" column); ``final_vs_single`` uses ``R[T, j]``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from nsl.errors import ConfigError

from .records import PerformanceMatrix, Rate


def _mean(values) -> float | None:
    vals = [v for v in values if v is not None]
    return float(np.mean(vals)) if vals else None


def curve_auc(steps, success) -> float:
    """Area under a success curve, normalised by its step range (a value in [0, 1])."""
    s = np.asarray(steps, dtype=float)
    v = np.asarray(success, dtype=float)
    if len(s) != len(v) or len(s) < 2:
        raise ConfigError(
            f"a success curve needs at least 2 points with one step each; got {len(s)} steps, {len(v)} values"
        )
    if np.any(np.diff(s) <= 0):
        raise ConfigError("a success curve's steps must increase")
    return float(np.trapezoid(v, s) / (s[-1] - s[0]))


@dataclass(frozen=True)
class ContinualMetrics:
    """Every metric of a performance matrix; per-task dicts map task -> value (None: undefined)."""

    matrix: PerformanceMatrix
    trained_at: Mapping[str, int | None]  # t_j: the stage that trained each task
    average_final_success: float | None
    final: Mapping[str, float | None]
    own_stage: Mapping[str, float | None]
    forgetting: Mapping[str, float | None]
    forgetting_end: Mapping[str, float | None]
    backward_transfer: Mapping[str, float | None]
    forward_transfer: Mapping[str, float | None]
    forward_transfer_auc: Mapping[str, float | None]
    zero_shot_transfer: Mapping[str, float | None]
    vs_base: Mapping[str, float | None]
    vs_single: Mapping[str, float | None]
    final_vs_single: Mapping[str, float | None]

    @property
    def average_forgetting(self) -> float | None:
        return _mean(self.forgetting.values())

    @property
    def average_backward_transfer(self) -> float | None:
        return _mean(self.backward_transfer.values())

    @property
    def average_forward_transfer(self) -> float | None:
        return _mean(self.forward_transfer.values())

    @property
    def average_forward_transfer_auc(self) -> float | None:
        return _mean(self.forward_transfer_auc.values())

    def to_dict(self) -> dict:
        per_task = (
            "trained_at",
            "final",
            "own_stage",
            "forgetting",
            "forgetting_end",
            "backward_transfer",
            "forward_transfer",
            "forward_transfer_auc",
            "zero_shot_transfer",
            "vs_base",
            "vs_single",
            "final_vs_single",
        )
        return {
            "matrix": self.matrix.to_dict(),
            "stages_done": len(self.matrix.stages) - 1,
            "average_final_success": self.average_final_success,
            "average_forgetting": self.average_forgetting,
            "average_backward_transfer": self.average_backward_transfer,
            "average_forward_transfer": self.average_forward_transfer,
            "average_forward_transfer_auc": self.average_forward_transfer_auc,
            "per_task": {name: dict(getattr(self, name)) for name in per_task},
        }

    def markdown(self, intervals: bool = True) -> str:
        """Table 5.3's shape (continual / vs base / vs single per trained task) plus final success and forgetting."""
        m = self.matrix
        lines = ["| task | continual | vs base | vs single | final | forgetting |", "|---|---|---|---|---|---|"]
        order = [t for t in m.stages[1:]] + [t for t in m.tasks if t not in m.stages[1:]]
        for task in order:
            j = m.tasks.index(task)
            t = self.trained_at[task]
            own = m.rate(t, j) if t is not None else None
            final = m.rate(len(m.stages) - 1, j)
            lines.append(
                f"| {task} | {'-' if own is None else own.percent(intervals)} | "
                f"{_points(self.vs_base[task])} | {_points(self.vs_single[task])} | "
                f"{'-' if final is None else final.percent(intervals)} | {_points(self.forgetting[task])} |"
            )
        lines.append("")
        lines.append(
            f"Average final success {_pct(self.average_final_success)}; average forgetting "
            f"{_points(self.average_forgetting)} points; backward transfer "
            f"{_points(self.average_backward_transfer)} points; forward transfer "
            f"{_points(self.average_forward_transfer)} points"
            + (
                f" (AUC {self.average_forward_transfer_auc:+.2f})"
                if self.average_forward_transfer_auc is not None
                else ""
            )
            + "."
        )
        return "\n".join(lines)


def _points(v: float | None) -> str:
    return "-" if v is None else f"{100 * v:+.0f}"


def _pct(v: float | None) -> str:
    return "-" if v is None else f"{100 * v:.0f}%"


def continual_metrics(matrix: PerformanceMatrix) -> ContinualMetrics:
    """All metrics of :mod:`this module's docstring <nsl.eval.continual>` for a (possibly partial) matrix."""
    m = matrix
    if not m.success:
        raise ConfigError("the performance matrix has no rows yet; evaluate the initial checkpoint (stage 0) first")
    R = np.array([[np.nan if v is None else v for v in row] for row in m.success], dtype=float)
    T = len(m.stages) - 1

    def cell(i: int | None, j: int) -> float | None:
        if i is None or i < 0 or i > T or np.isnan(R[i, j]):
            return None
        return float(R[i, j])

    def diff(a: float | None, b: float | None) -> float | None:
        return None if a is None or b is None else a - b

    trained_at: dict[str, int | None] = {}
    for task in m.tasks:
        trained_at[task] = m.stages.index(task, 1) if task in m.stages[1:] else 0 if task == m.base_task else None
    out: dict[str, dict] = {
        k: {}
        for k in (
            "final",
            "own_stage",
            "forgetting",
            "forgetting_end",
            "backward_transfer",
            "forward_transfer",
            "forward_transfer_auc",
            "zero_shot_transfer",
            "vs_base",
            "vs_single",
            "final_vs_single",
        )
    }
    for j, task in enumerate(m.tasks):
        t = trained_at[task]
        final, own, initial = cell(T, j), cell(t, j), cell(0, j)
        out["final"][task] = final
        out["own_stage"][task] = own
        cells = [cell(i, j) for i in range(t, T)] if t is not None else []
        earlier = [v for v in cells if v is not None]
        out["forgetting"][task] = (max(earlier) - final) if earlier and final is not None else None
        out["forgetting_end"][task] = diff(own, final) if t is not None and t < T else None
        out["backward_transfer"][task] = diff(final, own) if t is not None and t < T else None
        ref = None if m.reference is None else m.reference.get(task)
        out["forward_transfer"][task] = diff(own, ref) if t is not None and t >= 1 else None
        out["forward_transfer_auc"][task] = _auc_transfer(m, task) if t is not None and t >= 1 else None
        out["zero_shot_transfer"][task] = diff(cell(t - 1, j), initial) if t is not None and t >= 1 else None
        out["vs_base"][task] = diff(own, initial) if t is not None and t >= 1 else None
        single = None if m.single is None else m.single.get(task)
        if single is not None:
            single_rate = Rate.of(single)
            if single_rate is None:
                raise ConfigError(f"the single-step success for {task!r} is not a number; store a fraction in [0, 1]")
            single = single_rate.success_rate
        out["vs_single"][task] = diff(own, single) if t is not None and t >= 1 else None
        out["final_vs_single"][task] = diff(final, single)
    return ContinualMetrics(m, trained_at, _mean(out["final"].values()), **out)


def _auc_transfer(m: PerformanceMatrix, task: str) -> float | None:
    if not m.curves or not m.reference_curves or task not in m.curves or task not in m.reference_curves:
        return None
    c, r = m.curves[task], m.reference_curves[task]
    auc, ref = curve_auc(c["steps"], c["success"]), curve_auc(r["steps"], r["success"])
    if ref >= 1.0:
        return None  # the reference is already perfect: transfer is undefined
    return (auc - ref) / (1.0 - ref)
