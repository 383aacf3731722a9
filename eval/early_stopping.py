"""Early stopping for offline fine-tuning, with simulator and offline criteria.

The trainer knows no simulator: it calls ``eval_fn(step, policy)`` every
``every`` steps and stops when the result says ``"stop"``.
:class:`EarlyStopMonitor` is such an ``eval_fn``.  It scores the policy with
the callables its caller gives it (simulator episodes on the target shift and
on the base task, and/or offline criteria computed from held-out target data),
records one :class:`~nsl.eval.records.CurveRow` per call in ``curve.csv`` and
decides with :class:`EarlyStopping`.

Offline criteria (no simulator; the caller computes Q-values with the learner)::

    soft_opc(q, success)        mean(Q | successful episode) - mean(Q)   (Irpan et al. 2019), higher is better
    q_ranking_auc(q, success)   P(Q of a success > Q of a failure), ties 1/2, higher is better
    td_error(q, target)         mean((Q - Bellman target)^2) on held-out transitions, lower is better
    q_mean                      the average Q of held-out transitions: a peak, then a decline, marks
                                overfitting in conservative offline RL (Kumar et al. 2021), so its maximum
    fqe                         fitted Q evaluation's estimate of the success rate (nsl.learners.fqe)

:func:`choose_steps` replays every criterion over a recorded curve and says
how far each one's chosen step is from the step evaluation shows is best.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from nsl.errors import ConfigError, CorruptDataError
from nsl.workspace import atomic_write_json

from .config import CRITERIA, EarlyStopConfig, EarlyStopping, EvalConfig  # noqa: F401  (re-exported)
from .records import CURVE_FILE, EARLY_STOP_FILE, OFFLINE_COLUMNS, CurveRow, Rate, read_curve, write_curve
from .success import SuccessRate, run_eval_episodes

# --- offline criteria -----------------------------------------------------------------------------------------------


def _q_and_labels(q: ArrayLike, success: ArrayLike, what: str) -> tuple[np.ndarray, np.ndarray]:
    qa = np.asarray(q, dtype=np.float64).ravel()
    sa = np.asarray(success, dtype=bool).ravel()
    if len(qa) != len(sa):
        raise ConfigError(f"{what}: got {len(qa)} Q-values for {len(sa)} success labels; pass one label per transition")
    if not np.isfinite(qa).all():
        raise ConfigError(f"{what}: Q-values contain NaN or infinity; the Q-function has diverged")
    if not sa.any():
        raise ConfigError(f"{what}: the held-out set has no successful transitions; hold out more target episodes")
    return qa, sa


def soft_opc(q: ArrayLike, success: ArrayLike) -> float:
    """SoftOPC: mean Q on transitions of successful episodes minus mean Q on all held-out transitions."""
    qa, sa = _q_and_labels(q, success, "SoftOPC")
    return float(qa[sa].mean() - qa.mean())


def q_ranking_auc(q: ArrayLike, success: ArrayLike) -> float:
    """Area under the ROC curve of Q separating successes from failures (Mann-Whitney, ties count 1/2)."""
    qa, sa = _q_and_labels(q, success, "Q-ranking AUC")
    if sa.all():
        raise ConfigError("Q-ranking AUC: the held-out set has no failed transitions; hold out more target episodes")
    from scipy.stats import mannwhitneyu

    n_pos, n_neg = int(sa.sum()), int((~sa).sum())
    u = mannwhitneyu(qa[sa], qa[~sa], method="asymptotic").statistic  # U of the successes, midranks over ties
    return float(u / (n_pos * n_neg))


def td_error(q: ArrayLike, target: ArrayLike) -> float:
    """Mean squared TD error of held-out transitions: mean((Q(s, a) - (r + gamma * max Q'(s', a')))^2)."""
    qa = np.asarray(q, dtype=np.float64).ravel()
    ta = np.asarray(target, dtype=np.float64).ravel()
    if len(qa) != len(ta) or len(qa) == 0:
        raise ConfigError(f"TD error: got {len(qa)} Q-values and {len(ta)} targets; pass one target per Q-value")
    if not (np.isfinite(qa).all() and np.isfinite(ta).all()):
        raise ConfigError("TD error: Q-values or targets contain NaN or infinity; the Q-function has diverged")
    return float(np.mean((qa - ta) ** 2))


def offline_scores(q: ArrayLike, success: ArrayLike, target: ArrayLike | None = None) -> dict:
    """All offline criteria at once: ``{"softopc", "auc", "td_error" (if target given), "q_mean"}``."""
    out = {
        "softopc": soft_opc(q, success),
        "auc": q_ranking_auc(q, success),
        "q_mean": float(np.mean(np.asarray(q, dtype=np.float64))),
    }
    if target is not None:
        out["td_error"] = td_error(q, target)
    return out


def held_out_episodes(n_episodes: int, fraction: float, seed: int) -> np.ndarray:
    """Sorted indices of the episodes to hold out (split by episode, never by transition)."""
    if n_episodes < 2:
        raise ConfigError(f"holding out episodes needs at least 2 episodes; got {n_episodes}")
    if not 0.0 < fraction < 1.0:
        raise ConfigError(f"held-out fraction {fraction!r} is out of range; use 0 < f < 1 (e.g. 0.1)")
    k = min(n_episodes - 1, max(1, round(fraction * n_episodes)))
    return np.sort(np.random.default_rng([int(seed), 7]).choice(n_episodes, size=k, replace=False))


# --- the stopping rule ----------------------------------------------------------------------------------------------

# --- the trainer's eval_fn ------------------------------------------------------------------------------------------

Scorer = Callable[[Any], "SuccessRate | Rate"]
OfflineScorer = Callable[[Any], Mapping[str, float]]


def _same(policy):
    return policy


def simulator_scorer(shift, config: EvalConfig, env_overrides: dict | None = None) -> Scorer:
    """``policy -> SuccessRate`` on ``shift`` (a ShiftSpec) with ``config``'s paired scene seeds."""

    def score(policy) -> SuccessRate:
        episodes = run_eval_episodes(functools.partial(_same, policy), shift, config, env_overrides, progress=False)
        return SuccessRate(shift.name, len(episodes), sum(e.success for e in episodes))

    return score


@dataclass
class EarlyStopMonitor:
    """An ``eval_fn(step, policy) -> dict`` for the trainer that records the curve and decides when to stop.

    ``score_target``/``score_base`` return a SuccessRate (or Rate) for a policy;
    ``offline`` returns ``{"softopc": .., "auc": .., "td_error": .., "q_mean": .., "fqe": ..}`` (any
    subset) for a policy.  ``on_best(step, policy)`` is called whenever the
    criterion improves (keep that checkpoint).  Calling it again after a
    resumed run drops the recorded rows from the resumed step on and replays
    the rest, so the decision is the same as without the interruption.
    """

    config: EarlyStopConfig
    run_dir: Path
    score_target: Scorer | None = None
    score_base: Scorer | None = None
    offline: OfflineScorer | None = None
    on_best: Callable[[int, Any], None] | None = None
    references: Mapping[str, float] = field(default_factory=dict)  # horizontal lines in the plot, e.g. scratch

    def __post_init__(self) -> None:
        self.run_dir = Path(self.run_dir)
        if self.config.criterion == "eval" and self.score_target is None:
            raise ConfigError("early-stop criterion 'eval' needs a target scorer (simulator episodes)")
        if self.config.criterion != "eval" and self.offline is None:
            raise ConfigError(f"early-stop criterion {self.config.criterion!r} needs offline scores from held-out data")
        path = self.run_dir / CURVE_FILE
        self.rows: list[CurveRow] = read_curve(path) if path.is_file() else []
        if self.rows:
            self._check_same_evaluations()
        self.stopper = self._replay(self.rows)

    def _check_same_evaluations(self) -> None:
        """A resumed curve must go on with the same scenes and episode counts, or its steps are not comparable."""
        old = load_early_stop(self.run_dir / EARLY_STOP_FILE).get("config", {})
        new = self.config.to_dict()
        changed = [k for k in ("seed", "episodes", "base_episodes") if k in old and old[k] != new[k]]
        if changed:
            was = ", ".join(f"{k} {old[k]}" for k in changed)
            raise ConfigError(
                f"{self.run_dir.name}: its curve was evaluated with {was}; resume with the same "
                "settings (--eval-scenes, --eval-episodes, --base-episodes) or train under a new --name"
            )

    def _replay(self, rows: list[CurveRow]) -> EarlyStopping:
        stopper = self.config.stopper()
        for r in rows:
            stopper.update(r.step, r.value(self.config.column))
        return stopper

    def __call__(self, step: int, policy) -> dict:
        self.rows = [r for r in self.rows if r.step < step]
        self.stopper = self._replay(self.rows)
        target = Rate.of(self.score_target(policy)) if self.score_target is not None else None
        base = Rate.of(self.score_base(policy)) if self.score_base is not None else None
        off = dict(self.offline(policy)) if self.offline is not None else {}
        unknown = sorted(set(off) - set(OFFLINE_COLUMNS))
        if unknown:
            raise ConfigError(f"offline scores {unknown} are unknown; return any of {', '.join(OFFLINE_COLUMNS)}")
        row = CurveRow(int(step), target, base, **{k: off.get(k) for k in OFFLINE_COLUMNS})
        self.rows.append(row)
        stop = self.stopper.update(row.step, row.value(self.config.column))
        write_curve(self.run_dir / CURVE_FILE, self.rows)
        self._write_summary()
        if self.on_best is not None and self.stopper.best_step == row.step:
            self.on_best(row.step, policy)
        out = {k: v for k, v in row.to_dict().items() if v is not None}
        return {**out, "stop": stop, "best_step": self.stopper.best_step, "criterion": self.config.criterion}

    def _write_summary(self) -> None:
        from nsl import code_version

        s = self.stopper.state_dict()
        atomic_write_json(
            self.run_dir / EARLY_STOP_FILE,
            {
                "config": self.config.to_dict(),
                "criterion": self.config.criterion,
                "mode": self.config.mode,
                "best_step": s["best_step"],
                "best_value": s["best_value"],
                "stopped_step": s["stopped_step"],
                "bad_evals": s["bad_evals"],
                "references": dict(self.references),
                "code_version": code_version(),
            },
        )


# --- how good is each criterion's choice? ---------------------------------------------------------------------------


@dataclass(frozen=True)
class CriterionChoice:
    """The step a criterion picks on a recorded curve, and the evaluated success there."""

    criterion: str  # eval | softopc | auc | td, or 'best' (hindsight: highest target success) or 'final'
    step: int
    stopped_at: int | None  # where the patience ran out (None: the curve ended first)
    target: Rate | None
    base: Rate | None
    step_gap: int | None  # step - the hindsight-best step
    target_regret: float | None  # best target success - target success at step (fraction)

    def to_dict(self) -> dict:
        return {
            "criterion": self.criterion,
            "step": self.step,
            "stopped_at": self.stopped_at,
            "target": None if self.target is None else self.target.to_dict(),
            "base": None if self.base is None else self.base.to_dict(),
            "step_gap": self.step_gap,
            "target_regret": self.target_regret,
        }


def choose_steps(
    rows: Sequence[CurveRow], patience: int | None = None, min_delta: float = 0.0
) -> dict[str, CriterionChoice]:
    """Replay every criterion present in ``rows``; ``patience=None`` picks the best of the whole curve.

    Returns ``{"best": .., "final": .., "eval": .., "softopc": .., ...}`` (the
    criteria that have values).  A criterion only sees the rows where it was
    measured.  Ties go to the earlier step.
    """
    rows = sorted(rows, key=lambda r: r.step)
    if not rows:
        raise ConfigError("choosing a step needs a curve with at least one evaluation; got none")
    by_step = {r.step: r for r in rows}
    picks: dict[str, tuple[int, int | None]] = {}
    measured = [(r, r.target) for r in rows if r.target is not None]
    if measured:
        best, _ = max(measured, key=lambda m: (m[1].success_rate, -m[0].step))
        picks["best"] = (best.step, None)
    for name, (column, mode) in CRITERIA.items():
        seen = [r for r in rows if r.value(column) is not None]
        if not seen:
            continue
        stopper = EarlyStopping(patience or len(seen) + 1, min_delta, mode)
        for r in seen:
            if stopper.update(r.step, r.value(column)):
                break
        picks[name] = (stopper.best_step if stopper.best_step is not None else seen[0].step, stopper.stopped_step)
    picks["final"] = (rows[-1].step, None)
    best_row = by_step[picks["best"][0]] if "best" in picks else None
    out = {}
    for name, (step, stopped) in picks.items():
        r = by_step[step]
        gap = None if best_row is None else step - best_row.step
        regret = None
        if best_row is not None and best_row.target is not None and r.target is not None:
            regret = best_row.target.success_rate - r.target.success_rate
        out[name] = CriterionChoice(name, step, stopped, r.target, r.base, gap, regret)
    return out


def choices_table(choices: Mapping[str, CriterionChoice]) -> str:
    """Markdown: one row per criterion with its step, successes (95% intervals) and distance from the best."""
    lines = [
        "| criterion | chosen step | stopped at | target success | base success | steps from best | "
        "target regret (points) |",
        "|---|---|---|---|---|---|---|",
    ]
    for c in choices.values():
        lines.append(
            f"| {c.criterion} | {c.step} | {'-' if c.stopped_at is None else c.stopped_at} | "
            f"{'-' if c.target is None else c.target.percent()} | {'-' if c.base is None else c.base.percent()} | "
            f"{'-' if c.step_gap is None else f'{c.step_gap:+d}'} | "
            f"{'-' if c.target_regret is None else f'{100 * c.target_regret:.0f}'} |"
        )
    return "\n".join(lines)


def load_early_stop(path: Path) -> dict:
    """An early_stop.json written by :class:`EarlyStopMonitor` (empty if absent)."""
    path = Path(path)
    if not path.is_file():
        return {}
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise CorruptDataError(f"{path} is not valid JSON ({e.msg}); delete it or rerun the training") from None
