"""The target network's rate: ``tau`` (SB3's and d3rlpy's, the fraction updated) beside ``polyak`` (the fraction
kept); one of them is stated and recorded, and a polyak that looks like a tau is refused in one line."""

from __future__ import annotations

import json

import pytest
import torch
from learner_factories import TINY_NET, tiny_train

from nsl.errors import ConfigError
from nsl.learners import TrainConfig, load_checkpoint, train


def _training(result) -> dict:
    return json.loads((result.checkpoint / "config.json").read_text())["training"]


def test_tau_is_one_minus_polyak_and_the_stated_one_is_recorded(random_sampler, tmp_path):
    by_polyak = train(
        tiny_train(steps=4, polyak=0.9), random_sampler, tmp_path / "polyak", net=TINY_NET, progress=False
    )
    by_tau = train(tiny_train(steps=4, tau=0.1), random_sampler, tmp_path / "tau", net=TINY_NET, progress=False)
    a, b = load_checkpoint(by_polyak.checkpoint).net.state_dict(), load_checkpoint(by_tau.checkpoint).net.state_dict()
    assert all(torch.allclose(a[k], b[k], atol=1e-6) for k in a)  # the same target network updates
    assert _training(by_tau)["tau"] == 0.1 and "polyak" not in _training(by_tau)
    assert _training(by_polyak)["polyak"] == 0.9 and "tau" not in _training(by_polyak)
    assert load_checkpoint(by_tau.checkpoint).training.tau == 0.1  # it loads back as stated
    # A config that states neither is recorded as before tau existed (so checkpoint ids made then hold).
    default = TrainConfig().to_dict()
    assert default["polyak"] == 0.995 and "tau" not in default
    assert TrainConfig.from_dict(default) == TrainConfig() == TrainConfig(polyak=0.995)
    assert TrainConfig(tau=0.005).target_polyak == pytest.approx(0.995)
    assert TrainConfig(tau=0.005).replace(polyak=0.99).to_dict()["polyak"] == 0.99  # stating one drops the other


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        (
            {"polyak": 0.005},
            "polyak 0.005 keeps only 0.5% of the target each step; you probably mean tau=0.005 (polyak=0.995)",
        ),
        ({"tau": 0.995}, "tau 0.995 replaces 99.5% of the target each step; you probably mean polyak=0.995"),
        ({"polyak": 0.99, "tau": 0.01}, "polyak 0.99 and tau 0.01 both given; state one of them"),
        ({"tau": 0.0}, "tau 0 is out of range"),
        ({"polyak": 1.0}, "polyak 1 is out of range; use [0.5, 1)"),
    ],
)
def test_a_misread_rate_is_refused_in_one_line(settings, message):
    with pytest.raises(ConfigError) as err:
        TrainConfig(**settings)
    assert message in str(err.value) and "\n" not in str(err.value)
