"""How good is each early-stopping criterion's pick, judged on scenes no criterion saw.

A long fine-tune keeps a checkpoint at every evaluation of its curve; each criterion (the simulator on
selection scenes, or an offline one on held-out target episodes, replayed by :func:`choose_steps`) picks
one.  Two more sets of scenes judge the picks:

* **the oracle's scenes**: every kept checkpoint is evaluated on them.  The best there is the oracle's
  pick, and each criterion's Spearman correlation across checkpoints is measured against them;
* **the reporting scenes**: each pick, and the oracle's, is evaluated there, on the shift and on the base
  task.  A pick's regret is the oracle's success minus the pick's, on the same scenes (paired), so the
  oracle is never scored on the scenes that chose it.

Two baselines need nothing: ``fixed`` (the recipe's step count) and ``final`` (the last step).
:func:`score_criteria` puts it together per shift and over shifts, with the hierarchical intervals of
:mod:`nsl.stats` (training seeds and scenes).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from nsl.errors import ConfigError

from .config import CRITERIA
from .early_stopping import choose_steps
from .records import CurveRow

ORACLE = "oracle"
BASELINES = ("fixed", "final")
WHOLE_CURVE = "eval-all"  # the simulator criterion without patience: the best of the whole selection curve
TASKS = ("target", "base", "regret")  # what a CriterionScore measures at the picks


@dataclass(frozen=True)
class JudgedRun:
    """One long fine-tune: its recorded curve and the judging scenes' outcomes.

    ``oracle_scenes[step]`` is the checkpoint's per-scene success on the oracle's scenes (the shift);
    ``reporting[(step, task)]``, task ``"target"`` or ``"base"``, its success on the reporting scenes.
    """

    tag: str
    shift: str
    seed: int
    rows: Sequence[CurveRow]
    oracle_scenes: Mapping[int, Sequence[bool]]
    reporting: Mapping[tuple[int, str], Sequence[bool]]


def curve_picks(rows: Sequence[CurveRow], patience: int | None, fixed_step: int) -> dict[str, int]:
    """Each criterion's step on the curve (with ``patience``, as a run that stops would), the whole-curve best
    on selection scenes, ``fixed`` and ``final``: every pick that needs nothing but the run's own records."""
    steps = sorted(r.step for r in rows)
    if not steps:
        raise ConfigError("judging criteria needs a recorded curve; this run has none")
    choices = choose_steps(rows, patience=patience)
    out = {name: c.step for name, c in choices.items() if name not in ("best", "final")}
    if "best" in choices:
        out[WHOLE_CURVE] = choices["best"].step
    if fixed_step not in steps:
        raise ConfigError(f"the fixed step {fixed_step} is not on the curve (steps {steps[0]}..{steps[-1]})")
    out["fixed"], out["final"] = fixed_step, steps[-1]
    return out


def run_picks(
    rows: Sequence[CurveRow], oracle_scenes: Mapping[int, Sequence[bool]], patience: int | None, fixed_step: int
) -> dict[str, int]:
    """:func:`curve_picks` and the oracle's: the best checkpoint on its own scenes (ties to the earlier step)."""
    out = curve_picks(rows, patience, fixed_step)
    steps = sorted(r.step for r in rows)
    missing = [s for s in steps if s not in oracle_scenes]
    if missing:
        raise ConfigError(f"checkpoints at steps {missing} have no oracle-scene outcomes; evaluate them first")
    out[ORACLE] = max(steps, key=lambda s: (sum(oracle_scenes[s]) / len(oracle_scenes[s]), -s))
    return out


def spearman(rows: Sequence[CurveRow], oracle_scenes: Mapping[int, Sequence[bool]], criterion: str) -> float | None:
    """Spearman's rank correlation between a criterion's value (oriented so that higher is better) and
    success on the oracle's scenes, across the run's checkpoints (None: unmeasured or constant)."""
    from scipy.stats import spearmanr

    column, mode = CRITERIA[criterion]
    pairs = []
    for r in rows:
        v = r.value(column)
        if v is not None and r.step in oracle_scenes:
            pairs.append((v, oracle_scenes[r.step]))
    if len(pairs) < 3:
        return None
    values = [v if mode == "max" else -v for v, _ in pairs]
    truth = [sum(o) / len(o) for _, o in pairs]
    if len(set(values)) < 2 or len(set(truth)) < 2:
        return None
    return float(spearmanr(values, truth).statistic)


@dataclass(frozen=True)
class CriterionScore:
    """A criterion on one shift (or on the mean over shifts, ``shift`` None): its picks and how they fared."""

    criterion: str
    shift: str | None
    steps: tuple[int, ...]  # the step picked in each run
    target: Any  # HierarchicalGain: success on the reporting scenes at the picks
    base: Any  # HierarchicalGain: base-task success at the picks
    regret: Any  # HierarchicalGain: the oracle's success minus the pick's (paired, per run)
    rho: float | None  # Spearman's rho, the mean over runs

    def to_dict(self) -> dict:
        return {
            "criterion": self.criterion,
            "shift": self.shift,
            "steps": list(self.steps),
            "target": self.target.to_dict(),
            "base": self.base.to_dict(),
            "regret": self.regret.to_dict(),
            "rho": self.rho,
        }


def needed_reporting(runs: Sequence[JudgedRun], patience: int | None, fixed_step: int) -> dict[str, set[int]]:
    """The steps of each run (by tag) whose reporting-scene outcomes :func:`score_criteria` needs."""
    return {r.tag: set(run_picks(r.rows, r.oracle_scenes, patience, fixed_step).values()) for r in runs}


def score_criteria(
    runs: Sequence[JudgedRun], patience: int | None, fixed_step: int, *, n_boot: int = 2000, seed: int = 0
) -> list[CriterionScore]:
    """Every criterion's score per shift, then over shifts (``shift`` None), in the order criteria first appear.

    Every shift needs the same number of runs (seeds) and every run the same reporting scenes.  Intervals:
    :func:`nsl.stats.hierarchical_gain` over seeds and scenes per shift, :func:`nsl.stats.hierarchical_mean_gain`
    over shifts (their scenes shared, as scene i is the same layout on every shift)."""
    import numpy as np

    from nsl.stats import hierarchical_gain, hierarchical_mean_gain

    if not runs:
        raise ConfigError("no judged runs to score; evaluate the early-stopping runs first")
    by_shift: dict[str, list[JudgedRun]] = {}
    for r in runs:
        by_shift.setdefault(r.shift, []).append(r)
    sizes = {s: len(v) for s, v in by_shift.items()}
    if len(set(sizes.values())) != 1:
        raise ConfigError(f"every shift needs the same number of runs to average over shifts; got {sizes}")
    picks = {r.tag: run_picks(r.rows, r.oracle_scenes, patience, fixed_step) for r in runs}
    names = list(dict.fromkeys(n for p in picks.values() for n in p))

    def outcomes(run: JudgedRun, step: int, task: str) -> Any:
        got = run.reporting.get((step, task))
        if got is None:
            raise ConfigError(f"run {run.tag} has no reporting-scene outcomes at step {step} on the {task}")
        return np.asarray(got, dtype=np.float64)

    out = []
    for name in names:
        arrays: dict[str, list] = {"target": [], "base": [], "regret": []}
        for shift, shift_runs in by_shift.items():
            tgt = np.stack([outcomes(r, picks[r.tag][name], "target") for r in shift_runs])
            base = np.stack([outcomes(r, picks[r.tag][name], "base") for r in shift_runs])
            oracle = np.stack([outcomes(r, picks[r.tag][ORACLE], "target") for r in shift_runs])
            per = {"target": tgt, "base": base, "regret": oracle - tgt}
            for k, v in per.items():
                arrays[k].append(v)
            measured = [spearman(r.rows, r.oracle_scenes, name) for r in shift_runs] if name in CRITERIA else []
            rhos = [x for x in measured if x is not None]
            t, b, g = (hierarchical_gain(per[k][None], None, n_boot=n_boot, seed=seed) for k in TASKS)
            steps = tuple(picks[r.tag][name] for r in shift_runs)
            out.append(CriterionScore(name, shift, steps, t, b, g, float(np.mean(rhos)) if rhos else None))
        if len(by_shift) > 1:
            zeros = np.zeros((len(by_shift), arrays["target"][0].shape[1]))
            # each task's outcomes as (shifts, 1 collection, seeds, scenes)
            t, b, g = (
                hierarchical_mean_gain(np.stack(arrays[k])[:, None], zeros, n_boot=n_boot, seed=seed) for k in TASKS
            )
            shift_rhos = [
                x for x in (s.rho for s in out if s.criterion == name and s.shift is not None) if x is not None
            ]
            rho = float(np.mean(shift_rhos)) if shift_rhos else None
            out.append(CriterionScore(name, None, tuple(picks[r.tag][name] for r in runs), t, b, g, rho))
    return out


@dataclass(frozen=True)
class RefitScore:
    """Refit on one shift (``shift`` None: the mean over shifts): a criterion chose the step count on a run
    trained without its held-out episodes; the refit run trained on all of them to that step.  Each field is
    a HierarchicalGain over seeds and scenes on the reporting scenes."""

    criterion: str
    shift: str | None
    steps: tuple[int, ...]
    pick: Any  # the held-out run's success at the pick (the shift)
    refit: Any  # the refit run's success (the shift)
    gain: Any  # refit minus pick on the shift, paired per run: what refitting recovers of what holding out cost
    base_gain: Any  # the same on the base task


def score_refit(
    runs: Sequence[JudgedRun],
    refits: Mapping[str, Mapping[str, Sequence[bool]]],
    criterion: str,
    patience: int | None,
    fixed_step: int,
    *,
    n_boot: int = 2000,
    seed: int = 0,
) -> list[RefitScore]:
    """Refit against the held-out pick, per shift and over shifts.  ``refits[tag][task]`` (task ``"target"``
    or ``"base"``) is the refit run's per-scene success on the reporting scenes, its run trained on every
    target episode for the step count ``criterion`` chose on run ``tag``."""
    import numpy as np

    from nsl.stats import hierarchical_gain, hierarchical_mean_gain

    by_shift: dict[str, list[JudgedRun]] = {}
    for r in runs:
        if r.tag not in refits:
            raise ConfigError(f"run {r.tag} has no refit outcomes; run the refit for {criterion!r} first")
        by_shift.setdefault(r.shift, []).append(r)
    if not by_shift:
        raise ConfigError("no judged runs to compare refit with; evaluate the early-stopping runs first")
    sizes = {s: len(v) for s, v in by_shift.items()}
    if len(set(sizes.values())) != 1:
        raise ConfigError(f"every shift needs the same number of runs to average over shifts; got {sizes}")

    step_of = {r.tag: curve_picks(r.rows, patience, fixed_step)[criterion] for r in runs}

    def at(run: JudgedRun, task: str) -> Any:
        step = step_of[run.tag]
        got = run.reporting.get((step, task))
        if got is None:
            raise ConfigError(f"run {run.tag} has no reporting-scene outcomes at step {step} on the {task}")
        return np.asarray(got, dtype=np.float64)

    def refit(run: JudgedRun, task: str) -> Any:
        return np.asarray(refits[run.tag][task], dtype=np.float64)

    fields = ("pick", "refit", "gain", "base_gain")
    arrays: dict[str, list] = {k: [] for k in fields}
    out = []
    for shift, shift_runs in by_shift.items():
        pick = np.stack([at(r, "target") for r in shift_runs])
        ref = np.stack([refit(r, "target") for r in shift_runs])
        base = np.stack([refit(r, "base") - at(r, "base") for r in shift_runs])
        per = {"pick": pick, "refit": ref, "gain": ref - pick, "base_gain": base}
        for k in fields:
            arrays[k].append(per[k])
        steps = tuple(step_of[r.tag] for r in shift_runs)
        got = [hierarchical_gain(per[k][None], None, n_boot=n_boot, seed=seed) for k in fields]
        out.append(RefitScore(criterion, shift, steps, *got))
    if len(by_shift) > 1:
        zeros = np.zeros((len(by_shift), arrays["pick"][0].shape[1]))
        got = [hierarchical_mean_gain(np.stack(arrays[k])[:, None], zeros, n_boot=n_boot, seed=seed) for k in fields]
        out.append(RefitScore(criterion, None, tuple(s for o in out for s in o.steps), *got))
    return out
