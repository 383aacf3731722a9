"""Paired evaluation in the real simulator: equal seeds give two policies identical scenes."""

from __future__ import annotations

import functools

import numpy as np

from nsl.collectors import EnvConfig, parse_shift, scripted_policy
from nsl.eval import (
    EarlyStopConfig,
    EarlyStopMonitor,
    EvalConfig,
    compare_paired,
    evaluate_outcomes,
    read_curve,
    run_eval_episodes,
    simulator_scorer,
    success_rate_from_outcomes,
)

N = 6


def _factory(ref: str):
    env = EnvConfig()
    return functools.partial(scripted_policy, ref, control=env.control, move_step=env.move_step, yaw_step=env.yaw_step)


def test_two_policies_see_identical_scenes_with_the_same_seed():
    shift = parse_shift("base")
    cfg = EvalConfig(episodes=N, batch=N, seed=11)
    oracle = run_eval_episodes(_factory("oracle"), shift, cfg, progress=False)
    rand = run_eval_episodes(_factory("random"), shift, cfg, progress=False)
    other_seed = run_eval_episodes(_factory("oracle"), shift, EvalConfig(episodes=N, batch=N, seed=12), progress=False)
    for a, b, c in zip(oracle, rand, other_seed):
        assert a.index == b.index
        assert np.array_equal(a.images[0], b.images[0]), "the first observation (the scene) must be identical"
        assert not np.array_equal(a.images[0], c.images[0]), "another seed must give another scene"
        assert not np.array_equal(a.actions, b.actions)


def test_paired_outcomes_feed_mcnemar():
    shift = parse_shift("base")
    cfg = EvalConfig(episodes=N, batch=N, seed=11)
    a = evaluate_outcomes(_factory("oracle"), [shift], cfg, progress=False)["base"]
    b = evaluate_outcomes(_factory("random"), [shift], cfg, progress=False)["base"]
    assert len(a) == len(b) == N
    c = compare_paired(a, b, "oracle", "random")
    assert c.success_a == success_rate_from_outcomes("base", a).success_rate
    assert c.both + c.only_a + c.only_b + c.neither == N and 0.0 < c.p_value <= 1.0


def test_monitor_drives_the_simulator_with_the_same_scenes_at_every_step(tmp_path):
    cfg = EarlyStopConfig(episodes=4, base_episodes=4, patience=2, seed=5)
    target, base = parse_shift("harsh_lighting"), parse_shift("base")
    mon = EarlyStopMonitor(
        cfg,
        tmp_path,
        score_target=simulator_scorer(target, cfg.eval_config(batch=4)),
        score_base=simulator_scorer(base, cfg.eval_config(base=True, batch=4)),
    )
    policy = scripted_policy("oracle")
    out = [mon(step, policy) for step in (0, 100, 200)]
    # the same policy on the same scenes: identical outcomes, so no improvement and a stop after 2 evaluations
    assert [o["stop"] for o in out] == [False, False, True] and out[-1]["best_step"] == 0
    rows = read_curve(tmp_path / "curve.csv")
    assert len({r.target.success_rate for r in rows}) == 1 and rows[0].target.episodes == 4
    assert rows[0].base.episodes == 4
