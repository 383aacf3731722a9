"""The CEM policy follows the collectors' policy interface."""

from __future__ import annotations

import functools
import pickle

import numpy as np
import pytest

from nsl.errors import ConfigError
from nsl.learners import CEMPolicy, load_policy


def _obs(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {"image": rng.integers(0, 256, (n, 16, 16, 3), dtype=np.uint8),
            "state": rng.random((n, 6), dtype=np.float32)}


def test_policy_acts_in_the_active_dims_and_fills_the_others(parent_checkpoint):
    policy = load_policy(parent_checkpoint)
    actions = policy(_obs(4), rngs=[np.random.default_rng(i) for i in range(4)])
    assert actions.shape == (4, 6) and actions.dtype == np.float32
    assert np.all(np.abs(actions) <= 1.0)
    assert np.all(actions[:, 2] == 0.0) and np.all(actions[:, 4] == -1.0)  # dz and close are not searched
    assert policy.needs_privileged is False
    info = policy.describe()
    assert info["checkpoint"] == str(parent_checkpoint) and len(info["checkpoint_id"]) == 64


def test_an_episode_acts_the_same_whatever_its_batch(parent_checkpoint):
    policy = load_policy(parent_checkpoint)
    obs = _obs(5)
    batch = policy(obs, rngs=[np.random.default_rng([7, i]) for i in range(5)])
    alone = policy({k: v[3:4] for k, v in obs.items()}, rngs=[np.random.default_rng([7, 3])])
    np.testing.assert_allclose(batch[3], alone[0], atol=1e-6)


def test_load_policy_pickles_as_a_partial_and_takes_cem_overrides(parent_checkpoint):
    factory = pickle.loads(pickle.dumps(functools.partial(load_policy, parent_checkpoint, samples=8, elites=2)))
    policy = factory()
    assert isinstance(policy, CEMPolicy) and policy.cem.samples == 8 and policy.cem.elites == 2
    with pytest.raises(ConfigError, match="unknown CEM setting"):
        load_policy(parent_checkpoint, sampels=8)


def test_epsilon_greedy_explores(parent_checkpoint):
    greedy = load_policy(parent_checkpoint)
    explorer = load_policy(parent_checkpoint, epsilon=1.0)
    obs = _obs(6)
    a = greedy(obs, rngs=[np.random.default_rng(i) for i in range(6)])
    b = explorer(obs, rngs=[np.random.default_rng(i) for i in range(6)])
    assert not np.allclose(a[:, [0, 1, 3, 5]], b[:, [0, 1, 3, 5]])
    assert np.all(b[:, 4] == -1.0)
    with pytest.raises(ConfigError, match="epsilon"):
        load_policy(parent_checkpoint, epsilon=1.5)


def test_images_of_the_wrong_size_are_refused(parent_checkpoint):
    policy = load_policy(parent_checkpoint)
    bad = {"image": np.zeros((1, 32, 32, 3), np.uint8), "state": np.zeros((1, 6), np.float32)}
    with pytest.raises(ConfigError, match="images must be uint8"):
        policy(bad, rngs=[np.random.default_rng(0)])
