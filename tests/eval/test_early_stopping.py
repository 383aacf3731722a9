"""Early stopping: the rule, the offline criteria, the trainer's eval_fn and the choice of steps."""

from __future__ import annotations

import numpy as np
import pytest

from nsl.errors import ConfigError
from nsl.eval import (
    CurveRow,
    EarlyStopConfig,
    EarlyStopMonitor,
    EarlyStopping,
    Rate,
    choices_table,
    choose_steps,
    held_out_episodes,
    offline_scores,
    q_ranking_auc,
    read_curve,
    soft_opc,
    td_error,
)

# A Fig. 5.7-like curve: rises to a peak at step 5000, then collapses below the start.
STEPS = [0, 1000, 2000, 3000, 4000, 5000, 6000, 7000, 8000, 9000]
TARGET = [0.40, 0.50, 0.62, 0.70, 0.78, 0.86, 0.80, 0.66, 0.50, 0.30]


def test_early_stopping_picks_the_peak_and_stops_exactly_after_patience():
    es = EarlyStopping(patience=3)
    stops = [es.update(s, v) for s, v in zip(STEPS, TARGET)]
    # peak at 5000; non-improving evaluations at 6000, 7000, 8000 -> stop at the third
    assert stops == [False] * 8 + [True, True]
    assert es.best_step == 5000 and es.best_value == pytest.approx(0.86)
    assert es.stopped_step == 8000 and es.bad_evals == 4
    assert es.history[:3] == [(0, 0.40), (1000, 0.50), (2000, 0.62)] and len(es.history) == 10


def test_min_delta_counts_small_gains_as_no_improvement_and_min_mode():
    es = EarlyStopping(patience=2, min_delta=0.05)
    assert not es.update(0, 0.50)
    assert not es.update(1, 0.53)  # +0.03 < min_delta: first non-improving
    assert es.update(2, 0.54)  # second: stop
    assert es.best_step == 0
    td = EarlyStopping(patience=1, mode="min")
    assert not td.update(0, 0.3) and not td.update(1, 0.2) and td.update(2, float("nan"))
    assert td.best_step == 1


def test_a_new_best_resets_the_patience():
    es = EarlyStopping(patience=2)
    for step, v in enumerate([0.5, 0.4, 0.6, 0.5, 0.55]):
        stop = es.update(step, v)
    assert stop and es.best_step == 2 and es.stopped_step == 4


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"patience": 0}, "patience 0 must be an integer of at least 1"),
        ({"patience": 2, "mode": "up"}, "mode 'up' is unknown"),
        ({"patience": 2, "min_delta": -1}, "min_delta -1 must be >= 0"),
    ],
)
def test_bad_early_stopping_settings(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        EarlyStopping(**kwargs)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"criterion": "loss"}, "criterion 'loss' is unknown; use one of eval, softopc, auc, td"),
        ({"episodes": 0}, "criterion 'eval' needs episodes >= 1"),
        ({"every": 0}, "every 0 must be at least 1"),
        ({"held_out": 1.5}, "held_out 1.5 must be between 0 and 1"),
    ],
)
def test_bad_early_stop_config(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        EarlyStopConfig(**kwargs)


def test_early_stop_config_round_trips_and_builds_eval_configs():
    cfg = EarlyStopConfig(every=500, episodes=20, base_episodes=10, criterion="softopc", seed=7)
    assert EarlyStopConfig.from_dict(cfg.to_dict()) == cfg
    assert cfg.mode == "max" and EarlyStopConfig(criterion="td").mode == "min"
    assert cfg.eval_config().episodes == 20 and cfg.eval_config(base=True).episodes == 10
    assert cfg.eval_config(workers=2).seed == 7
    with pytest.raises(ConfigError, match=r"unknown early-stop setting\(s\) \['patiense'\]"):
        EarlyStopConfig.from_dict({"patiense": 3})


# --- offline criteria ---------------------------------------------------------------------------------------------


def _held_out(seed=0, n_episodes=40, steps=6):
    rng = np.random.default_rng(seed)
    success = np.repeat(rng.random(n_episodes) < 0.4, steps)
    return rng, success


def test_soft_opc_ranks_the_checkpoint_that_separates_successes_higher():
    rng, success = _held_out()
    noise = rng.normal(0, 0.1, len(success))
    sharp = 0.3 + 0.5 * success + noise  # Q separates successes well
    blurry = 0.3 + 0.1 * success + noise
    assert soft_opc(sharp, success) > soft_opc(blurry, success) > 0
    assert q_ranking_auc(sharp, success) > q_ranking_auc(blurry, success) > 0.5
    # by definition: mean over successes minus mean over all
    assert soft_opc(sharp, success) == pytest.approx(sharp[success].mean() - sharp.mean())


def test_auc_by_hand_with_ties():
    q = [0.9, 0.5, 0.5, 0.1]
    success = [True, True, False, False]
    # pairs (success, failure): (0.9>0.5) 1, (0.9>0.1) 1, (0.5=0.5) 1/2, (0.5>0.1) 1 -> 3.5 / 4
    assert q_ranking_auc(q, success) == pytest.approx(0.875)
    assert q_ranking_auc([0.1, 0.9], [True, False]) == 0.0


def test_td_error_and_offline_scores():
    assert td_error([0.5, 0.2], [0.7, 0.2]) == pytest.approx(0.02)
    s = offline_scores([0.9, 0.1, 0.8, 0.2], [1, 0, 1, 0], target=[1.0, 0.0, 1.0, 0.0])
    assert s["auc"] == 1.0 and s["softopc"] == pytest.approx(0.85 - 0.5) and s["td_error"] == pytest.approx(0.025)


def test_offline_criteria_reject_unusable_held_out_sets():
    with pytest.raises(ConfigError, match="no successful transitions"):
        soft_opc([0.1, 0.2], [False, False])
    with pytest.raises(ConfigError, match="no failed transitions"):
        q_ranking_auc([0.1, 0.2], [True, True])
    with pytest.raises(ConfigError, match="got 3 Q-values for 2 success labels"):
        soft_opc([0.1, 0.2, 0.3], [True, False])
    with pytest.raises(ConfigError, match="diverged"):
        td_error([float("nan")], [0.0])


def test_held_out_episodes_is_deterministic_and_never_everything():
    a = held_out_episodes(100, 0.1, seed=3)
    assert len(a) == 10 and list(a) == sorted(set(a)) and np.array_equal(a, held_out_episodes(100, 0.1, seed=3))
    assert not np.array_equal(a, held_out_episodes(100, 0.1, seed=4))
    assert len(held_out_episodes(3, 0.9, seed=0)) == 2


# --- choosing steps on a recorded curve -----------------------------------------------------------------------------


def _curve_rows():
    softopc = [0.05, 0.07, 0.09, 0.10, 0.12, 0.11, 0.13, 0.09, 0.06, 0.04]  # peaks late, at 6000
    td = [0.20, 0.15, 0.12, 0.10, 0.09, 0.08, 0.085, 0.09, 0.11, 0.14]  # lowest at 5000
    return [
        CurveRow(s, Rate(t, 50), Rate(0.86, 50), softopc=o, td_error=d)
        for s, t, o, d in zip(STEPS, TARGET, softopc, td)
    ]


def test_choose_steps_reports_each_criterion_against_the_best_step():
    choices = choose_steps(_curve_rows())
    assert set(choices) == {"best", "eval", "softopc", "td", "final"}
    assert choices["best"].step == 5000 and choices["best"].step_gap == 0
    assert choices["eval"].step == 5000 and choices["eval"].target_regret == 0
    assert choices["td"].step == 5000
    assert choices["softopc"].step == 6000 and choices["softopc"].step_gap == 1000
    assert choices["softopc"].target_regret == pytest.approx(0.06)
    assert choices["final"].step == 9000 and choices["final"].target_regret == pytest.approx(0.56)
    assert choices["eval"].base.success_rate == 0.86
    table = choices_table(choices)
    assert "| softopc | 6000 | - | 80% [67-89] |" in table and "+1000 | 6 |" in table


def test_choose_steps_with_patience_stops_where_the_live_rule_would():
    choices = choose_steps(_curve_rows(), patience=1)
    # softopc falls at 5000 (0.11 < 0.12): with patience 1 it stops there and keeps 4000
    assert choices["softopc"].step == 4000 and choices["softopc"].stopped_at == 5000
    assert choices["eval"].step == 5000 and choices["eval"].stopped_at == 6000


# --- the trainer's eval_fn -------------------------------------------------------------------------------------------


class _Scripted:
    """Returns the next value of a fixed curve on each call (what a simulator would measure)."""

    def __init__(self, values):
        self.values, self.calls = list(values), 0

    def __call__(self, policy):
        v = self.values[self.calls]
        self.calls += 1
        return Rate(v, 50)


def test_monitor_records_the_curve_stops_and_keeps_the_best(tmp_path):
    best_calls = []
    mon = EarlyStopMonitor(
        EarlyStopConfig(every=1000, patience=3),
        tmp_path,
        score_target=_Scripted(TARGET),
        score_base=_Scripted([0.86] * 10),
        on_best=lambda step, policy: best_calls.append(step),
    )
    results = []
    for step in STEPS:
        results.append(mon(step, policy=f"policy@{step}"))
        if results[-1]["stop"]:
            break
    assert [r["step"] for r in results] == STEPS[:9] and results[-1]["stop"] and results[-1]["best_step"] == 5000
    assert best_calls == [0, 1000, 2000, 3000, 4000, 5000]
    rows = read_curve(tmp_path / "curve.csv")
    assert [r.step for r in rows] == STEPS[:9]
    assert rows[5].target.success_rate == pytest.approx(0.86) and rows[5].target.episodes == 50
    assert rows[5].base.ci == pytest.approx(Rate(0.86, 50).ci)
    assert results[0]["target_ci_low"] == pytest.approx(Rate(0.40, 50).ci[0])


def test_monitor_resumes_with_the_same_decision(tmp_path):
    cfg = EarlyStopConfig(every=1000, patience=3)
    full = EarlyStopMonitor(cfg, tmp_path / "full", score_target=_Scripted(TARGET))
    decisions = [full(s, None)["stop"] for s in STEPS[:9]]
    # interrupted after step 6000; the trainer resumes from its step-4000 checkpoint and evaluates 5000 again
    part = EarlyStopMonitor(cfg, tmp_path / "part", score_target=_Scripted(TARGET[:7]))
    for s in STEPS[:7]:
        part(s, None)
    resumed = EarlyStopMonitor(cfg, tmp_path / "part", score_target=_Scripted(TARGET[5:]))
    assert resumed.stopper.best_step == 5000  # replayed from curve.csv
    after = [resumed(s, None)["stop"] for s in STEPS[5:9]]
    assert after == decisions[5:9]
    assert read_curve(tmp_path / "part" / "curve.csv") == read_curve(tmp_path / "full" / "curve.csv")


def test_a_resumed_curve_must_keep_its_scenes(tmp_path):
    first = EarlyStopMonitor(
        EarlyStopConfig(every=1000, patience=3, seed=3000), tmp_path, score_target=_Scripted(TARGET)
    )
    first(0, None)
    first(1000, None)
    with pytest.raises(ConfigError, match=r"evaluated with seed 3000; resume with the same settings \(--eval-scenes"):
        EarlyStopMonitor(EarlyStopConfig(every=1000, patience=3, seed=2000), tmp_path, score_target=_Scripted(TARGET))
    same = EarlyStopMonitor(
        EarlyStopConfig(every=1000, patience=3, seed=3000), tmp_path, score_target=_Scripted(TARGET)
    )
    assert [r.step for r in same.rows] == [0, 1000]


def test_monitor_with_an_offline_criterion_needs_no_simulator(tmp_path):
    cfg = EarlyStopConfig(episodes=0, base_episodes=0, criterion="td", patience=2)
    values = iter([0.3, 0.2, 0.25, 0.26])
    mon = EarlyStopMonitor(cfg, tmp_path, offline=lambda policy: {"td_error": next(values), "q_mean": 0.4})
    out = [mon(s, None) for s in (0, 10, 20, 30)]
    assert [o["stop"] for o in out] == [False, False, False, True] and out[-1]["best_step"] == 10
    assert "target_success" not in out[0]
    with pytest.raises(ConfigError, match="criterion 'td' needs offline scores"):
        EarlyStopMonitor(cfg, tmp_path)
    with pytest.raises(ConfigError, match="criterion 'eval' needs a target scorer"):
        EarlyStopMonitor(EarlyStopConfig(), tmp_path)
