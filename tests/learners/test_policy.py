"""The CEM policy follows the collectors' policy interface."""

from __future__ import annotations

import functools
import json
import pickle

import numpy as np
import pytest

from nsl.errors import ConfigError
from nsl.learners import CEMPolicy, load_policy


def _obs(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {
        "image": rng.integers(0, 256, (n, 16, 16, 3), dtype=np.uint8),
        "state": rng.random((n, 6), dtype=np.float32),
    }


def test_policy_acts_in_the_active_dims_and_fills_the_others(parent_checkpoint):
    policy = load_policy(parent_checkpoint)
    actions = policy(_obs(4), rngs=[np.random.default_rng(i) for i in range(4)])
    assert actions.shape == (4, 6) and actions.dtype == np.float32
    assert np.all(np.abs(actions) <= 1.0)
    assert np.all(actions[:, 2] == 0.0) and np.all(actions[:, 4] == -1.0)  # dz and close are not searched
    assert policy.needs_privileged is False
    info = policy.describe()
    assert len(info["checkpoint_id"]) == 64 and info["step"] > 0
    # the description goes into the hashed metadata of datasets: no folder path, so no workspace location
    assert str(parent_checkpoint.parent) not in json.dumps(info)


def test_an_episode_acts_the_same_whatever_its_batch(parent_checkpoint):
    policy = load_policy(parent_checkpoint)
    obs = _obs(5)
    batch = policy(obs, rngs=[np.random.default_rng([7, i]) for i in range(5)])
    alone = policy({k: v[3:4] for k, v in obs.items()}, rngs=[np.random.default_rng([7, 3])])
    np.testing.assert_array_equal(batch[3], alone[0])


def test_greedy_actions_and_q_values_are_the_same_bits_in_any_batch_and_thread_count():
    """The shipped base on rendered harsh-lighting frames: batched network passes would round differently."""
    import torch

    from nsl.collectors import EnvConfig, GraspEnv
    from nsl.workspace import shipped_base_dir

    env = GraspEnv(EnvConfig(shift="harsh_lighting"))
    frames = []
    try:
        for seed in range(3):
            o, _ = env.reset(seed=seed)
            frames.append(o)
            for _ in range(2):
                o, *_ = env.step(np.array([0.5, -0.3, 0.0, 0.2, -1.0, -1.0], np.float32))
                frames.append(o)
    finally:
        env.close()
    obs = {k: np.stack([f[k] for f in frames]) for k in ("image", "state")}
    n = len(frames)
    policy = load_policy(shipped_base_dir())

    def rngs(idx):
        return [np.random.default_rng([11, i]) for i in idx]

    threads = torch.get_num_threads()
    try:
        torch.set_num_threads(2)
        batch = policy.greedy(obs, rngs(range(n)))
        torch.set_num_threads(1)
        for size in (1, 4):
            for s in range(0, n, size):
                part = policy.greedy({k: v[s : s + size] for k, v in obs.items()}, rngs(range(s, min(s + size, n))))
                np.testing.assert_array_equal(part[0], batch[0][s : s + size])  # actions
                np.testing.assert_array_equal(part[1], batch[1][s : s + size])  # their Q logits, to the last bit
    finally:
        torch.set_num_threads(threads)


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


def test_action_noise_explores_near_the_greedy_action_and_is_recorded_only_when_used(parent_checkpoint):
    greedy = load_policy(parent_checkpoint)
    noisy = load_policy(parent_checkpoint, action_noise=0.2)
    obs = _obs(64)
    a = greedy(obs, rngs=[np.random.default_rng(i) for i in range(64)])
    b = noisy(obs, rngs=[np.random.default_rng(i) for i in range(64)])
    again = noisy(obs, rngs=[np.random.default_rng(i) for i in range(64)])
    np.testing.assert_array_equal(b, again)  # the noise comes from each episode's generator
    searched = [0, 1, 3, 5]  # the parent's active dims; dz and close stay fixed
    diff = (b - a)[:, searched]
    assert np.all(diff != 0) or np.any(np.abs(b[:, searched]) == 1.0)  # every action moved, unless clipped
    assert 0.1 < diff[np.abs(b[:, searched]) < 1.0].std() < 0.3  # about the asked std, not a uniform action
    assert np.all(b[:, 2] == a[:, 2]) and np.all(b[:, 4] == -1.0)
    assert noisy.describe()["action_noise"] == 0.2
    assert "action_noise" not in greedy.describe()  # older datasets' hashed policy descriptions stay the same
    with pytest.raises(ConfigError, match="action_noise"):
        load_policy(parent_checkpoint, action_noise=-0.1)


def test_images_of_the_wrong_size_are_refused(parent_checkpoint):
    policy = load_policy(parent_checkpoint)
    bad = {"image": np.zeros((1, 32, 32, 3), np.uint8), "state": np.zeros((1, 6), np.float32)}
    with pytest.raises(ConfigError, match="images must be uint8"):
        policy(bad, rngs=[np.random.default_rng(0)])
