"""The in-memory sampler: transitions from arrays and episodes (mixing by weight is the dataset loader's)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from learner_factories import random_transitions

from nsl import keys
from nsl.errors import ConfigError
from nsl.learners import ArraySampler


def _episode(t, value, terminated=True):
    return SimpleNamespace(
        images=np.full((t, 4, 4, 3), value, np.uint8),
        states=np.stack([np.zeros(t), np.arange(t), *np.zeros((4, t))], 1).astype(np.float32),
        actions=np.zeros((t, 6), np.float32),
        rewards=np.eye(t, dtype=np.float32)[-1] * (value % 2),
        terminated=terminated,
    )


def test_episodes_become_transitions_with_next_observations():
    s = ArraySampler.from_episodes([_episode(3, 1), _episode(2, 2), _episode(2, 5, terminated=False)])
    assert len(s) == 3 + 2 + 1  # the truncated episode's last transition has no next observation
    batch = s.sample(200, np.random.default_rng(0))
    assert set(batch) == {
        keys.OBS_IMAGE,
        keys.OBS_STATE,
        keys.ACTION,
        keys.REWARD,
        keys.DONE,
        keys.NEXT_OBS_IMAGE,
        keys.NEXT_OBS_STATE,
    }
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


def test_inconsistent_arrays_are_refused():
    t = random_transitions(4)
    with pytest.raises(ConfigError, match="lack key"):
        ArraySampler.from_transitions({k: v for k, v in t.items() if k != keys.REWARD})
    with pytest.raises(ConfigError, match=r"actions has shape \(4, 5\)"):
        ArraySampler(
            t[keys.OBS_IMAGE], t[keys.OBS_STATE], t[keys.ACTION][:, :5], t[keys.REWARD], t[keys.DONE], np.arange(4)
        )
