"""CEM: finds the maximum, is deterministic given its noise, and draws each state's noise from its own rng."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from nsl.learners import CemConfig, cem_maximize, noise_from_generator, noise_from_rngs


def _peaked(goal: torch.Tensor):
    return lambda cand: -((cand - goal.unsqueeze(1)) ** 2).sum(-1)


def test_cem_finds_the_peak_of_a_known_function():
    goal = torch.tensor([[0.6, -0.3, 0.0, 0.9], [-0.8, 0.2, 0.5, -0.1]])
    cfg = CemConfig(samples=64, elites=6, iterations=3)
    best, score = cem_maximize(_peaked(goal), noise_from_generator(2, 4, cfg, torch.Generator().manual_seed(0)), cfg)
    assert best.shape == (2, 4) and score.shape == (2,)
    assert torch.allclose(best, goal, atol=0.15)
    assert torch.allclose(score, _peaked(goal)(best.unsqueeze(1)).squeeze(1))


def test_cem_respects_the_action_bounds():
    goal = torch.tensor([[3.0, -3.0]])  # outside [-1, 1]: the best feasible action is the corner
    cfg = CemConfig(samples=32, elites=4, iterations=3)
    best, _ = cem_maximize(_peaked(goal), noise_from_generator(1, 2, cfg, torch.Generator().manual_seed(1)), cfg)
    assert best.abs().max() <= 1.0
    assert torch.allclose(best, torch.tensor([[1.0, -1.0]]))


def test_more_iterations_do_not_lose_the_best_candidate():
    goal = torch.tensor([[0.2, 0.7]])
    base = CemConfig(samples=16, elites=4, iterations=1)
    more = CemConfig(samples=16, elites=4, iterations=4)
    g = torch.Generator().manual_seed(3)
    noise = noise_from_generator(1, 2, more, g)
    _, s1 = cem_maximize(_peaked(goal), noise[:, :1], base)
    _, s4 = cem_maximize(_peaked(goal), noise, more)
    assert s4 >= s1


def test_noise_is_reproducible_and_per_state():
    cfg = CemConfig(samples=8, elites=2, iterations=2)
    a = noise_from_generator(3, 4, cfg, torch.Generator().manual_seed(5))
    b = noise_from_generator(3, 4, cfg, torch.Generator().manual_seed(5))
    assert torch.equal(a, b) and a.shape == (3, 2, 8, 4)
    together = noise_from_rngs([np.random.default_rng(i) for i in range(3)], 4, cfg)
    alone = noise_from_rngs([np.random.default_rng(2)], 4, cfg)
    assert torch.equal(together[2], alone[0])


def test_noise_of_the_wrong_shape_is_refused():
    cfg = CemConfig(samples=8, elites=2, iterations=2)
    with pytest.raises(ValueError, match="CEM noise has shape"):
        cem_maximize(lambda c: c.sum(-1), torch.zeros(1, 3, 8, 2), cfg)
