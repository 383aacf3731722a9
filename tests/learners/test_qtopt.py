"""The QT-Opt step: clipped double-Q targets from the target networks, and the target-network updates."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from learner_factories import TINY_CEM, TINY_NET, random_transitions, tiny_train

from nsl import keys
from nsl.errors import ConfigError
from nsl.learners import (
    ArraySampler,
    CemConfig,
    Learner,
    QNetwork,
    bellman_target,
    cem_maximize,
    noise_from_generator,
    train,
    update,
)
from nsl.learners.qtopt import batch_to_torch


def _constant(net: QNetwork, p: float) -> QNetwork:
    """Make ``net`` output P(success) = p for every input."""
    with torch.no_grad():
        net.columns[-1].out.weight.zero_()
        net.columns[-1].out.bias.fill_(torch.logit(torch.tensor(p)).item())
    return net


def _next(n=6):
    g = torch.Generator().manual_seed(0)
    return torch.rand(n, 3, 16, 16, generator=g), torch.rand(n, 6, generator=g)


def test_target_is_reward_plus_discounted_minimum_of_the_two_target_networks():
    image, state = _next()
    reward = torch.tensor([0.0, 1.0, 0.0, 0.0, 1.0, 0.0])
    done = torch.tensor([0.0, 0.0, 1.0, 0.0, 1.0, 0.0])
    noise = noise_from_generator(6, 4, TINY_CEM, torch.Generator().manual_seed(1))
    for p_polyak, p_lagged in ((0.8, 0.6), (0.3, 0.7)):
        polyak, lagged = _constant(QNetwork(TINY_NET), p_polyak), _constant(QNetwork(TINY_NET), p_lagged)
        target, value = bellman_target(polyak, lagged, image, state, reward, done, 0.9, TINY_CEM, noise)
        v = min(p_polyak, p_lagged)
        expected = reward + 0.9 * (1 - done) * v
        assert torch.allclose(target, expected, atol=1e-6)
        assert torch.allclose(value, (1 - done) * v, atol=1e-6)


def test_n_step_batches_bootstrap_with_their_own_discount(tmp_path):
    image, state = _next()
    reward, done = torch.zeros(6), torch.zeros(6)
    discount = torch.tensor([0.9, 0.81, 0.729, 0.9, 0.81, 0.729])
    noise = noise_from_generator(6, 4, TINY_CEM, torch.Generator().manual_seed(1))
    polyak, lagged = _constant(QNetwork(TINY_NET), 0.5), _constant(QNetwork(TINY_NET), 0.5)
    target, _ = bellman_target(polyak, lagged, image, state, reward, done, discount, TINY_CEM, noise)
    assert torch.allclose(target, 0.5 * discount, atol=1e-6)
    # update() takes the batch's DISCOUNT in place of gamma: with discount 0 the target is the reward.
    batch = random_transitions(16, done_rate=0.0)
    stats = {}
    for name, extra in (("gamma", {}), ("zero", {keys.DISCOUNT: np.zeros(16, np.float32)})):
        learner = Learner.create(QNetwork(TINY_NET), 1e-3, tiny_train())
        stats[name] = update(learner, batch_to_torch({**batch, **extra}), tiny_train(), 0)
    assert stats["zero"]["q/target_mean"] == pytest.approx(batch[keys.REWARD].mean(), abs=1e-6)
    assert stats["gamma"]["q/target_mean"] > stats["zero"]["q/target_mean"] + 0.1
    # A trainer refuses a sampler whose transitions do not match its n_step.
    with pytest.raises(ConfigError, match="1-step transitions .* n_step 3"):
        train(tiny_train(n_step=3), ArraySampler.from_transitions(batch), tmp_path / "run", progress=False)


def test_target_maximises_the_polyak_network_and_evaluates_both_networks_there():
    torch.manual_seed(0)
    polyak, lagged = QNetwork(TINY_NET), QNetwork(TINY_NET)
    image, state = _next(4)
    zeros = torch.zeros(4)
    cem = CemConfig(samples=32, elites=4, iterations=2)
    noise = noise_from_generator(4, 4, cem, torch.Generator().manual_seed(2))
    target, value = bellman_target(polyak, lagged, image, state, zeros, zeros, 0.9, cem, noise)
    with torch.no_grad():
        ctx = polyak.encode(image, state)
        first_round = polyak.score(ctx, noise[:, 0].clamp(-1, 1) * cem.init_std).max(1).values
        a_star, logit_star = cem_maximize(lambda c: polyak.score(ctx, c), noise, cem)
        q_lagged = torch.sigmoid(lagged(image, state, a_star))
    assert torch.all(logit_star >= first_round - 1e-6)  # CEM's choice beats every first-round candidate
    assert torch.allclose(value, torch.minimum(torch.sigmoid(logit_star), q_lagged), atol=1e-6)
    assert torch.allclose(target, 0.9 * value)


def test_update_trains_the_online_network_and_moves_the_targets():
    torch.manual_seed(0)
    cfg = tiny_train(polyak=0.9, lag_period=3)
    learner = Learner.create(QNetwork(TINY_NET), 1e-3, cfg)
    batch = batch_to_torch(random_transitions(16))
    before = {k: v.clone() for k, v in learner.online.state_dict().items()}
    polyak_before = {k: v.clone() for k, v in learner.polyak.state_dict().items()}
    lagged_before = {k: v.clone() for k, v in learner.lagged.state_dict().items()}
    metrics = update(learner, batch, cfg, step=0)
    assert set(metrics) >= {"losses/q_loss", "q/mean", "q/target_mean", "q/next_value_mean"}
    assert all(isinstance(v, float) for v in metrics.values())
    online = learner.online.state_dict()
    name = "columns.0.out.bias"
    assert not torch.equal(online[name], before[name])
    expected = 0.9 * polyak_before[name] + 0.1 * online[name]
    assert torch.allclose(learner.polyak.state_dict()[name], expected, atol=1e-7)
    assert torch.equal(learner.lagged.state_dict()[name], lagged_before[name])  # not yet refreshed
    update(learner, batch, cfg, step=1)
    update(learner, batch, cfg, step=2)  # the third step refreshes the lagged copy
    assert torch.equal(learner.lagged.state_dict()[name], learner.online.state_dict()[name])


def test_augmentation_changes_the_inputs_only_when_enabled():
    from nsl.learners.augment import prepare_images

    images = torch.from_numpy(random_transitions(4)[keys.OBS_IMAGE])
    g = torch.Generator().manual_seed(0)
    plain = prepare_images(images, 0, 0.0, g)
    assert torch.allclose(plain, images.permute(0, 3, 1, 2).float() / 255)
    shifted = prepare_images(images, 2, 0.0, g)
    jittered = prepare_images(images, 0, 0.3, g)
    assert shifted.shape == jittered.shape == plain.shape
    assert not torch.equal(shifted, plain) and not torch.equal(jittered, plain)
    assert set(shifted.unique().tolist()) <= set(plain.unique().tolist())  # a shift only moves pixels
    assert jittered.min() >= 0 and jittered.max() <= 1


def test_conservative_term_keeps_unseen_actions_below_the_data_actions():
    """Every data action is near dx = 0.5 and succeeds 70% of the time. Plain QT-Opt extrapolates that to
    dx = -1, which the data never tried; with the CQL term the unseen actions stay well below the data's."""
    import numpy as np

    data = random_transitions(64, done_rate=1.0)
    data[keys.ACTION][:, 0] = np.random.default_rng(1).uniform(0.4, 0.6, 64)
    data[keys.REWARD][:] = (np.arange(64) % 10 < 7).astype(np.float32)
    batch = batch_to_torch(data)
    unseen = batch[keys.ACTION].clone()
    unseen[:, 0] = -1.0

    def q_after_training(alpha: float) -> tuple[float, float]:
        torch.manual_seed(0)
        cfg = tiny_train(conservative=alpha, augment_crop=0, augment_colour=0.0)
        learner = Learner.create(QNetwork(TINY_NET), 3e-3, cfg)
        for step in range(150):
            metrics = update(learner, batch, cfg, step)
        assert (metrics["losses/conservative"] > 0) == (alpha > 0)
        from nsl.learners.augment import prepare_images
        from nsl.learners.cem import active_actions

        with torch.no_grad():
            img = prepare_images(batch[keys.OBS_IMAGE], 0, 0.0, None)

            def q(a):
                return torch.sigmoid(learner.online(img, batch[keys.OBS_STATE], active_actions(a, TINY_NET))).mean()

            return float(q(batch[keys.ACTION])), float(q(unseen))

    plain_data, plain_unseen = q_after_training(0.0)
    cql_data, cql_unseen = q_after_training(1.0)
    assert plain_data > 0.6 and plain_unseen > 0.5  # plain QT-Opt: the unseen action looks good too
    assert cql_data > 0.5 and cql_unseen < cql_data - 0.3 and cql_unseen < plain_unseen - 0.3  # measured 0.58, 0.00
