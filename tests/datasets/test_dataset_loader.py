"""The training loader's contract: transitions, terminal handling, mixing by weight, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from nsl import keys
from nsl.datasets import api
from nsl.errors import ConfigError

BATCH_SPEC = {
    keys.OBS_IMAGE: ((16, 16, 3), np.uint8),
    keys.NEXT_OBS_IMAGE: ((16, 16, 3), np.uint8),
    keys.OBS_STATE: ((6,), np.float32),
    keys.NEXT_OBS_STATE: ((6,), np.float32),
    keys.ACTION: ((6,), np.float32),
    keys.REWARD: ((), np.float32),
    keys.DONE: ((), np.float32),
}


def test_transitions_follow_episodes_and_skip_truncated_ends(make_synth):
    lengths = [3, 4, 2, 5]
    v = make_synth("moves", lengths, truncated={1}, successes={2})
    s = api.make_sampler("moves")
    assert len(s) == sum(lengths) - 1  # the truncated episode's last frame has no successor
    b = s.sample(4000, np.random.default_rng(0))
    assert {k: (a.shape[1:], a.dtype) for k, a in b.items()} == BATCH_SPEC

    ep, t = b[keys.OBS_IMAGE][:, 0, 0, 0], b[keys.OBS_IMAGE][:, 0, 0, 1]
    nep, nt = b[keys.NEXT_OBS_IMAGE][:, 0, 0, 0], b[keys.NEXT_OBS_IMAGE][:, 0, 0, 1]
    last = np.array(lengths)[ep] - 1
    assert len(set(zip(ep.tolist(), t.tolist()))) == len(s)  # every transition is drawn
    assert not np.any((ep == 1) & (t == last)), "the last frame of a truncated episode has no transition"
    terminal = t == last
    np.testing.assert_array_equal(b[keys.DONE], terminal.astype(np.float32))
    np.testing.assert_array_equal(ep, nep)
    np.testing.assert_array_equal(nt[~terminal], t[~terminal] + 1)
    np.testing.assert_array_equal(b[keys.REWARD], ((ep == 2) & terminal).astype(np.float32))
    # States and actions belong to the same frames as the images.
    np.testing.assert_allclose(b[keys.OBS_STATE][:, 1], t / 10.0, rtol=1e-6)
    np.testing.assert_allclose(b[keys.NEXT_OBS_STATE][~terminal, 1], nt[~terminal] / 10.0, rtol=1e-6)
    actions = v.view().read_columns()[keys.ACTION]
    starts = np.r_[0, np.cumsum(lengths)[:-1]]
    np.testing.assert_array_equal(b[keys.ACTION], actions[starts[ep] + t])


def test_mixing_by_weight_and_reproducible_batches(make_synth):
    make_synth("base", [4] * 6, state_offset=0.0)
    make_synth("target", [5] * 3, state_offset=1.0)
    s = api.make_sampler([("base", 0.5), ("data:target:2", 0.5)])
    d = s.describe()
    assert [src["ref"] for src in d["sources"]] == ["base@v1", "target@v1:2"]
    assert [src["weight"] for src in d["sources"]] == [0.5, 0.5] and d["sources"][1]["episodes"] == 2
    assert len(s) == 24 + 10
    from_target = np.concatenate([s.sample(256, np.random.default_rng(i))[keys.OBS_STATE][:, 0] for i in range(20)])
    assert abs(from_target.mean() - 0.5) < 0.03  # 5120 draws: 4.3 standard deviations
    tier = api.make_sampler("target:2").sample(512, np.random.default_rng(1))
    assert set(np.unique(tier[keys.OBS_IMAGE][:, 0, 0, 0])) == {0, 1}  # a tier holds its first episodes only
    skewed = api.make_sampler([("base", 9), ("target", 1)]).sample(4000, np.random.default_rng(0))
    assert abs(skewed[keys.OBS_STATE][:, 0].mean() - 0.1) < 0.02
    a, b = (s.sample(32, np.random.default_rng(7)) for _ in range(2))
    assert all(np.array_equal(a[k], b[k]) for k in a)


def test_sampler_errors_are_one_line(make_synth):
    make_synth("base", [3, 3])
    with pytest.raises(ConfigError, match="weight -1 of base must be a positive number"):
        api.make_sampler([("base", -1)])
    with pytest.raises(ConfigError, match="at least one"):
        api.make_sampler([])
    with pytest.raises(ConfigError, match="holdout 2 of base@v1"):
        api.episode_split("base", 2)


def test_n_step_transitions_follow_the_data_to_the_episode_end(make_synth):
    lengths, gamma, n = [3, 4, 2, 6], 0.5, 3
    make_synth("chains", lengths, truncated={1}, successes={2, 3})
    one, s = api.make_sampler("chains"), api.make_sampler("chains", n_step=n, gamma=gamma)
    assert (
        len(s) == len(one)
        and s.describe()["n_step"] == n
        and keys.DISCOUNT not in one.sample(4, np.random.default_rng(0))
    )
    b = s.sample(4000, np.random.default_rng(0))
    ep, t = b[keys.OBS_IMAGE][:, 0, 0, 0].astype(int), b[keys.OBS_IMAGE][:, 0, 0, 1].astype(int)
    nep, nt = b[keys.NEXT_OBS_IMAGE][:, 0, 0, 0].astype(int), b[keys.NEXT_OBS_IMAGE][:, 0, 0, 1].astype(int)
    length = np.array(lengths)[ep]
    truncated, success = ep == 1, np.isin(ep, [2, 3])
    # A terminated episode ends within the chain when its last frame is at most n - 1 frames ahead.
    k = np.where(truncated, np.minimum(n, length - 1 - t), np.minimum(n, length - t))
    terminal = ~truncated & (t + k == length)
    np.testing.assert_array_equal(b[keys.DONE], terminal.astype(np.float32))
    np.testing.assert_array_equal(nep, ep)
    np.testing.assert_array_equal(nt[~terminal], (t + k)[~terminal])
    np.testing.assert_allclose(b[keys.DISCOUNT][~terminal], gamma ** k[~terminal])
    np.testing.assert_allclose(b[keys.REWARD], np.where(terminal & success, gamma ** (k - 1), 0.0))
    np.testing.assert_allclose(b[keys.NEXT_OBS_STATE][~terminal, 1], nt[~terminal] / 10.0, rtol=1e-6)
    assert set(k[terminal & success]) == {1, 2, 3} and set(k[~terminal]) == {1, 2, 3}  # all cases were drawn
    with pytest.raises(ConfigError, match="need the discount gamma"):
        api.make_sampler("chains", n_step=2)
    with pytest.raises(ConfigError, match="n_step 0"):
        api.make_sampler("chains", n_step=0, gamma=0.9)
