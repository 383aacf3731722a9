"""The learner finds a known answer on a tiny synthetic offline dataset."""

from __future__ import annotations

import numpy as np
import pytest
from learner_factories import TINY_NET, colour_task, tiny_train

from nsl.learners import ArraySampler, CemConfig, NetConfig, load_policy, train


@pytest.mark.parametrize("augment,pool", [(False, "flatten"), (True, "flatten"), (False, "spatial")])
def test_greedy_cem_action_lands_in_the_only_successful_region(tmp_path, augment, pool):
    data = colour_task(2000)
    cfg = tiny_train(
        steps=400,
        batch_size=32,
        lr=3e-3,
        checkpoint_every=400,
        log_every=100,
        augment_crop=2 if augment else 0,
        augment_colour=0.1 if augment else 0.0,
    )
    net = NetConfig.from_dict({**TINY_NET.to_dict(), "pool": pool})
    result = train(cfg, ArraySampler.from_transitions(data), tmp_path / "run", net=net, progress=False)
    policy = load_policy(result.checkpoint, samples=64, elites=6, iterations=3)
    test = colour_task(40, seed=1)
    obs = {"image": test["observation.image"], "state": test["observation.state"]}
    actions = policy(obs, rngs=[np.random.default_rng(i) for i in range(40)])
    red = test["observation.image"][:, 0, 0, 0] > 150
    hit = np.where(red, actions[:, 0] > 0.5, actions[:, 0] < -0.5)
    assert hit.mean() >= 0.95, f"only {hit.mean():.0%} of greedy actions are in the successful region"
    q = policy.q_values(obs, actions)
    wrong = actions.copy()
    wrong[:, 0] = -wrong[:, 0]
    assert np.mean(q > policy.q_values(obs, wrong) + 0.3) >= 0.9
    assert policy.cem == CemConfig(samples=64, elites=6, iterations=3)
