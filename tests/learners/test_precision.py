"""Mixed precision: bf16 runs are deterministic and resume bit for bit; fp32 is today's step; auto falls back."""

from __future__ import annotations

import json

import pytest
import torch
from learner_factories import TINY_NET, tiny_train
from test_resume import _Crash, _CrashingSampler

from nsl.errors import ConfigError
from nsl.learners import checkpoint_id, load_checkpoint, load_policy, precision, train

pytestmark = pytest.mark.precision  # make test runs these again with NSL_BF16=0
needs_bf16 = pytest.mark.skipif(not precision.bf16_supported(), reason="this CPU has no bfloat16 arithmetic")


def _weights(result):
    return load_checkpoint(result.checkpoint).net.state_dict()


def _same(a, b) -> bool:
    return all(torch.equal(a[k], b[k]) for k in a)


@needs_bf16
def test_a_bf16_run_is_deterministic_resumes_bit_for_bit_and_differs_from_fp32(random_sampler, tmp_path):
    cfg = tiny_train(steps=16, checkpoint_every=8, lag_period=5, augment_crop=2, precision="bf16")
    one = train(cfg, random_sampler, tmp_path / "one", net=TINY_NET, progress=False)
    two = train(cfg, random_sampler, tmp_path / "two", net=TINY_NET, progress=False)
    assert _same(_weights(one), _weights(two))
    with pytest.raises(_Crash):
        train(cfg, _CrashingSampler(random_sampler, crash_at=11), tmp_path / "killed", net=TINY_NET, progress=False)
    resumed = train(cfg, random_sampler, tmp_path / "killed", net=TINY_NET, progress=False)
    assert _same(_weights(one), _weights(resumed))
    fp32 = train(cfg.replace(precision="fp32"), random_sampler, tmp_path / "fp32", net=TINY_NET, progress=False)
    assert not _same(_weights(one), _weights(fp32))  # the option changes the arithmetic
    # weights stay float32, and the checkpoint records the precision it was trained in
    assert all(v.dtype == torch.float32 for v in _weights(one).values() if v.is_floating_point())
    assert json.loads((one.checkpoint / "config.json").read_text())["training"]["precision"] == "bf16"


def test_fp32_is_the_step_and_the_checkpoint_of_a_run_without_the_option(random_sampler, tmp_path):
    cfg = tiny_train(steps=6, checkpoint_every=3)
    assert cfg.precision == "fp32"
    default = train(cfg, random_sampler, tmp_path / "default", net=TINY_NET, progress=False)
    explicit = train(cfg.replace(precision="fp32"), random_sampler, tmp_path / "fp32", net=TINY_NET, progress=False)
    assert _same(_weights(default), _weights(explicit))
    # fp32 is not written into the config, so checkpoints made before the option keep their ids
    assert "precision" not in json.loads((default.checkpoint / "config.json").read_text())["training"]
    assert checkpoint_id(default.checkpoint) == checkpoint_id(explicit.checkpoint)


def test_auto_falls_back_without_bf16_and_bf16_then_fails_in_one_line(random_sampler, tmp_path, monkeypatch):
    monkeypatch.setattr(precision, "bf16_supported", lambda: False)
    assert precision.resolve_precision("auto") == "fp32"
    run = train(tiny_train(steps=2, precision="auto"), random_sampler, tmp_path / "auto", net=TINY_NET, progress=False)
    assert "precision" not in json.loads((run.checkpoint / "config.json").read_text())["training"]  # resolved: fp32
    with pytest.raises(ConfigError, match="precision bf16 needs a CPU with AVX-512 BF16 or AMX") as err:
        train(tiny_train(steps=2, precision="bf16"), random_sampler, tmp_path / "bf16", net=TINY_NET, progress=False)
    assert "\n" not in str(err.value)
    with pytest.raises(ConfigError, match="precision 'fp16' is unknown"):
        precision.resolve_precision("fp16")


@needs_bf16
def test_a_policy_acts_in_the_precision_asked_and_says_so(random_sampler, tmp_path):
    import numpy as np

    run = train(tiny_train(steps=2), random_sampler, tmp_path / "run", net=TINY_NET, progress=False)
    fp32, bf16 = load_policy(run.checkpoint), load_policy(run.checkpoint, precision="bf16")
    assert "precision" not in fp32.describe() and bf16.describe()["precision"] == "bf16"
    n = TINY_NET.image_size
    obs = {"image": np.zeros((2, n, n, 3), np.uint8), "state": np.zeros((2, TINY_NET.state_dim), np.float32)}
    rngs = [np.random.default_rng(0), np.random.default_rng(1)]
    a16 = bf16(obs, rngs=[np.random.default_rng(0), np.random.default_rng(1)])
    assert a16.shape == fp32(obs, rngs=rngs).shape and a16.dtype == np.float32
    q = bf16.q_values(obs, a16)
    assert q.dtype == np.float32 and np.all((q >= 0) & (q <= 1))


@pytest.mark.parametrize("channels_last", [True, False])
def test_the_trunk_input_is_the_images_and_coordinates_in_the_callers_layout_and_autocast_dtype(channels_last):
    from nsl.learners import NetConfig, QNetwork
    from nsl.learners.augment import to_float
    from nsl.learners.networks import coordinate_planes

    net = QNetwork(NetConfig(image_size=16))
    pixels = torch.randint(0, 256, (3, 16, 16, 3), dtype=torch.uint8, generator=torch.Generator().manual_seed(0))
    image = to_float(pixels, channels_last=channels_last)
    expected = torch.cat([image - 0.5, coordinate_planes(16).expand(3, -1, -1, -1)], 1)
    x = net.input(image)
    assert torch.equal(x, expected) and x.dtype == torch.float32
    assert x.is_contiguous(memory_format=torch.channels_last if channels_last else torch.contiguous_format)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        x16 = net.input(image)
    assert x16.dtype == torch.bfloat16 and torch.equal(x16, expected.to(torch.bfloat16))  # what the cast would give


def test_a_bf16_run_updates_with_fused_adam_and_fp32_with_torchs_default():
    from nsl.learners import NetConfig, QNetwork, TrainConfig
    from nsl.learners.qtopt import Learner

    net = QNetwork(NetConfig(image_size=16))
    assert Learner.create(net, 1e-3, TrainConfig(precision="bf16")).optimizer.defaults["fused"] is True
    assert Learner.create(net, 1e-3, TrainConfig()).optimizer.defaults["fused"] is None  # the loop fp32 always ran


def test_nsl_bf16_0_makes_any_cpu_a_cpu_without_bfloat16(monkeypatch):
    """The switch the suite runs under to check CPUs without bfloat16 (and a user's way to keep auto at fp32)."""
    for off in ("0", "off", "False"):
        monkeypatch.setenv(precision.BF16_ENV, off)
        assert not precision.bf16_supported()
        assert precision.resolve_precision("auto") == "fp32"
        with pytest.raises(ConfigError, match="precision bf16 needs a CPU"):
            precision.resolve_precision("bf16")
    monkeypatch.delenv(precision.BF16_ENV)
    monkeypatch.setattr(torch._C, "_cpu", None, raising=False)  # a torch that cannot say: no bfloat16
    assert not precision.bf16_supported()
