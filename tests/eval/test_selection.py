"""Judging early-stopping criteria: picks, the oracle, regret and rank correlation on hand-made runs."""

import numpy as np
import pytest

from nsl.errors import ConfigError
from nsl.eval.records import CurveRow, Rate
from nsl.eval.selection import (
    ORACLE,
    WHOLE_CURVE,
    JudgedRun,
    curve_picks,
    needed_reporting,
    run_picks,
    score_criteria,
    score_refit,
    spearman,
)

STEPS = [0, 500, 1000, 1500, 2000]
SCENES = 400


def outcomes(rate: float, seed: int, n: int = SCENES) -> list[bool]:
    """Exactly round(rate * n) successes on n scenes, in a seeded order."""
    k = round(rate * n)
    x = np.zeros(n, dtype=bool)
    x[:k] = True
    return list(np.random.default_rng(seed).permutation(x))


def make_run(shift: str, seed: int, truth: list[float], selection: list[float], qmean: list[float]) -> JudgedRun:
    rows = [
        CurveRow(s, target=Rate(sel, 200), base=Rate(0.8, 200), q_mean=q, td_error=1.0 - q)
        for s, sel, q in zip(STEPS, selection, qmean)
    ]
    oracle = {s: outcomes(t, 100 + i) for i, (s, t) in enumerate(zip(STEPS, truth))}
    reporting = {}
    for i, (s, t) in enumerate(zip(STEPS, truth)):
        reporting[(s, "target")] = outcomes(t, 200 + i)
        reporting[(s, "base")] = outcomes(0.9 - 0.1 * i, 300 + i)
    return JudgedRun(f"{shift}-s{seed}", shift, seed, rows, oracle, reporting)


# The truth peaks at step 1000; selection scenes peak there too; qmean peaks at 500; td is qmean mirrored.
# Ranks of the selection curve 1 4 5 3 2, of the truth 1 3 5 4 2: Spearman 1 - 6 * 2 / (5 * 24) = 0.9.
TRUTH = [0.5, 0.6, 0.7, 0.65, 0.55]
SELECTION = [0.48, 0.62, 0.71, 0.58, 0.52]
QMEAN = [0.3, 0.9, 0.5, 0.4, 0.2]


def test_picks_follow_each_criterion_and_the_oracle_takes_the_best_on_its_scenes():
    run = make_run("a", 0, TRUTH, SELECTION, QMEAN)
    picks = run_picks(run.rows, run.oracle_scenes, patience=None, fixed_step=1500)
    assert picks[ORACLE] == 1000 and picks["eval"] == 1000 and picks[WHOLE_CURVE] == 1000
    assert picks["qmean"] == 500 and picks["td"] == 500  # td: lowest error = highest qmean here
    assert picks["fixed"] == 1500 and picks["final"] == 2000
    # With patience 1 the simulator criterion stops at the first evaluation that does not improve.
    early = run_picks(run.rows, run.oracle_scenes, patience=1, fixed_step=1500)
    assert early["eval"] == 1000
    bumpy = [0.48, 0.62, 0.61, 0.75, 0.52]
    stopped = run_picks(make_run("a", 0, TRUTH, bumpy, QMEAN).rows, run.oracle_scenes, patience=1, fixed_step=0)
    assert stopped["eval"] == 500 and stopped[WHOLE_CURVE] == 1500


def test_picks_refuse_a_missing_checkpoint_or_a_fixed_step_off_the_curve():
    run = make_run("a", 0, TRUTH, SELECTION, QMEAN)
    with pytest.raises(ConfigError, match="fixed step 1200"):
        run_picks(run.rows, run.oracle_scenes, None, 1200)
    partial = {s: o for s, o in run.oracle_scenes.items() if s != 2000}
    with pytest.raises(ConfigError, match=r"steps \[2000\].*evaluate them first"):
        run_picks(run.rows, partial, None, 1000)


def test_spearman_is_oriented_so_that_higher_is_better():
    run = make_run("a", 0, TRUTH, SELECTION, QMEAN)
    rho_eval = spearman(run.rows, run.oracle_scenes, "eval")
    assert rho_eval == pytest.approx(0.9)
    # td is minimised: its orientation makes it equal to qmean's correlation, not its negative.
    assert spearman(run.rows, run.oracle_scenes, "td") == pytest.approx(spearman(run.rows, run.oracle_scenes, "qmean"))
    assert spearman(run.rows, run.oracle_scenes, "fqe") is None  # never measured


def test_regret_is_the_oracle_minus_the_pick_on_the_reporting_scenes():
    runs = [make_run(shift, seed, TRUTH, SELECTION, QMEAN) for shift in ("a", "b") for seed in (0, 1, 2)]
    need = needed_reporting(runs, patience=None, fixed_step=1500)
    assert need[runs[0].tag] == {500, 1000, 1500, 2000}
    scores = {(s.criterion, s.shift): s for s in score_criteria(runs, None, 1500, n_boot=400)}
    oracle = scores[(ORACLE, None)]
    assert oracle.regret.mean == 0 and oracle.regret.low == 0 and oracle.regret.high == 0
    q = scores[("qmean", "a")]
    assert q.steps == (500, 500, 500)
    assert q.regret.mean == pytest.approx(0.7 - 0.6)  # exact counts: 70% at the oracle's step, 60% at 500
    assert q.regret.low < 0.1 < q.regret.high and q.regret.high - q.regret.low < 0.15
    assert q.base.mean == pytest.approx(0.8)  # the base task at step 500
    assert scores[("final", None)].regret.mean == pytest.approx(0.7 - 0.55)
    assert scores[("final", None)].rho is None  # baselines have no values to rank
    assert scores[("eval", None)].rho == pytest.approx(0.9)


def test_scoring_needs_the_picks_outcomes_and_equal_runs_per_shift():
    runs = [make_run("a", 0, TRUTH, SELECTION, QMEAN), make_run("a", 1, TRUTH, SELECTION, QMEAN)]
    lopsided = [*runs, make_run("b", 0, TRUTH, SELECTION, QMEAN)]
    with pytest.raises(ConfigError, match="same number of runs"):
        score_criteria(lopsided, None, 1500)
    r = runs[0]
    thin = JudgedRun(
        r.tag, r.shift, r.seed, r.rows, r.oracle_scenes, {k: v for k, v in r.reporting.items() if k[0] != 500}
    )
    with pytest.raises(ConfigError, match="at step 500 on the target"):
        score_criteria([thin, runs[1]], None, 1500)


def test_refit_is_scored_against_the_held_out_pick_on_the_same_scenes():
    runs = [make_run(shift, seed, TRUTH, SELECTION, QMEAN) for shift in ("a", "b") for seed in (0, 1)]
    assert curve_picks(runs[0].rows, None, 1500)["qmean"] == 500  # no oracle needed to know the step count
    # Refit at qmean's step 500: 66% on the shift where the held-out run had 60%, the base task 2 points lower.
    refits = {r.tag: {"target": outcomes(0.66, 7), "base": outcomes(0.78, 8)} for r in runs}
    scores = {s.shift: s for s in score_refit(runs, refits, "qmean", None, 1500, n_boot=400)}
    a, mean = scores["a"], scores[None]
    assert a.steps == (500, 500) and mean.steps == (500,) * 4
    assert a.pick.mean == pytest.approx(0.6) and a.refit.mean == pytest.approx(0.66)
    assert a.gain.mean == pytest.approx(0.06) and mean.gain.mean == pytest.approx(0.06)
    assert a.gain.low < 0.06 < a.gain.high
    assert a.base_gain.mean == pytest.approx(0.78 - 0.8)
    with pytest.raises(ConfigError, match="no refit outcomes"):
        score_refit(runs, {runs[0].tag: refits[runs[0].tag]}, "qmean", None, 1500)
