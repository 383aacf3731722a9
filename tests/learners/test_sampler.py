"""In-memory samplers: transitions from arrays and episodes, and weighted mixtures."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from learner_factories import random_transitions

from nsl import keys
from nsl.errors import ConfigError
from nsl.learners import ArraySampler, MixtureSampler


def _episode(t, value, terminated=True):
    return SimpleNamespace(images=np.full((t, 4, 4, 3), value, np.uint8),
                           states=np.stack([np.zeros(t), np.arange(t), *np.zeros((4, t))], 1).astype(np.float32),
                           actions=np.zeros((t, 6), np.float32),
                           rewards=np.eye(t, dtype=np.float32)[-1] * (value % 2), terminated=terminated)


def test_episodes_become_transitions_with_next_observations():
    s = ArraySampler.from_episodes([_episode(3, 1), _episode(2, 2), _episode(2, 5, terminated=False)])
    assert len(s) == 3 + 2 + 1  # the truncated episode's last transition has no next observation
    batch = s.sample(200, np.random.default_rng(0))
    assert set(batch) == {keys.OBS_IMAGE, keys.OBS_STATE, keys.ACTION, keys.REWARD, keys.DONE,
                          keys.NEXT_OBS_IMAGE, keys.NEXT_OBS_STATE}
    live = batch[keys.DONE] == 0
    # within an episode the next frame is one step later and shows the same episode
    assert np.all(batch[keys.NEXT_OBS_STATE][live, 1] == batch[keys.OBS_STATE][live, 1] + 1)
    assert np.all(batch[keys.NEXT_OBS_IMAGE][live] == batch[keys.OBS_IMAGE][live])
    done_value = batch[keys.OBS_IMAGE][~live, 0, 0, 0]
    assert set(done_value.tolist()) <= {1, 2}  # only terminated episodes end in a terminal transition
    assert np.all(batch[keys.REWARD][~live] == done_value % 2)


def test_sampling_depends_only_on_the_rng():
    s = ArraySampler.from_transitions(random_transitions(50))
    a, b = s.sample(8, np.random.default_rng(3)), s.sample(8, np.random.default_rng(3))
    assert all(np.array_equal(a[k], b[k]) for k in a)
    assert a[keys.OBS_IMAGE].shape == (8, 16, 16, 3) and a[keys.DONE].dtype == np.float32


def test_mixture_draws_fixed_shares_and_describes_weights():
    base = ArraySampler.from_episodes([_episode(2, 2)], name="base")
    target = ArraySampler.from_episodes([_episode(2, 4)], name="target")
    mix = MixtureSampler([(base, 1.0), (target, 1.0)])
    batch = mix.sample(10, np.random.default_rng(0))
    assert (batch[keys.OBS_IMAGE][:, 0, 0, 0] == 2).sum() == 5
    assert MixtureSampler([(base, 3), (target, 1)]).counts(10) in ([8, 2], [7, 3])
    assert [(s["name"], s["weight"]) for s in mix.describe()["sources"]] == [("base", 0.5), ("target", 0.5)]
    with pytest.raises(ConfigError, match="positive weights"):
        MixtureSampler([(base, 0.0)])


class _Discounted(ArraySampler):
    """An n-step-style sampler: its batches also carry a per-transition discount."""

    def sample(self, batch_size, rng):
        return {**super().sample(batch_size, rng), keys.DISCOUNT: np.full(batch_size, 0.81, np.float32)}


def test_mixture_keeps_extra_keys_and_refuses_mixing_one_step_with_n_step():
    a = _Discounted.from_episodes([_episode(3, 2)], name="a")
    b = _Discounted.from_episodes([_episode(3, 4)], name="b")
    batch = MixtureSampler([(a, 1.0), (b, 1.0)]).sample(8, np.random.default_rng(0))
    np.testing.assert_array_equal(batch[keys.DISCOUNT], np.full(8, 0.81, np.float32))
    plain = ArraySampler.from_episodes([_episode(3, 4)], name="plain")
    with pytest.raises(ConfigError, match="different batch keys"):
        MixtureSampler([(a, 1.0), (plain, 1.0)]).sample(8, np.random.default_rng(0))


def test_inconsistent_arrays_are_refused():
    t = random_transitions(4)
    with pytest.raises(ConfigError, match="lack key"):
        ArraySampler.from_transitions({k: v for k, v in t.items() if k != keys.REWARD})
    with pytest.raises(ConfigError, match=r"actions has shape \(4, 5\)"):
        ArraySampler(t[keys.OBS_IMAGE], t[keys.OBS_STATE], t[keys.ACTION][:, :5], t[keys.REWARD], t[keys.DONE],
                     np.arange(4))
