"""Action maximisation by the cross-entropy method (CEM), batched over states.

For every state, CEM samples candidate actions from a Gaussian over the
active action components (clipped to [-1, 1]), scores them with the
Q-network's head, refits the Gaussian to the best few (the elites) and
repeats.  It returns the best candidate seen and its score.

All randomness comes in as a pre-drawn standard-normal tensor, so the result
is a pure function of its inputs.  :func:`noise_from_generator` draws it from
a ``torch.Generator`` (Bellman targets); :func:`noise_from_rngs` draws each
state's share from its own ``numpy.random.Generator`` (acting), so an
episode's actions do not depend on which other episodes share its batch.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import torch

from nsl.keys import ACTION_DIM

from .config import CemConfig, NetConfig


def noise_shape(batch: int, dims: int, cfg: CemConfig) -> tuple[int, int, int, int]:
    return (batch, cfg.iterations, cfg.samples, dims)


def noise_from_generator(batch: int, dims: int, cfg: CemConfig, generator: torch.Generator) -> torch.Tensor:
    return torch.randn(noise_shape(batch, dims, cfg), generator=generator, device=generator.device)


def noise_from_rngs(rngs: Sequence[np.random.Generator], dims: int, cfg: CemConfig) -> torch.Tensor:
    per = [rng.standard_normal((cfg.iterations, cfg.samples, dims), dtype=np.float32) for rng in rngs]
    return torch.from_numpy(np.stack(per)) if per else torch.zeros(noise_shape(0, dims, cfg))


def cem_maximize(
    score: Callable[[torch.Tensor], torch.Tensor], noise: torch.Tensor, cfg: CemConfig
) -> tuple[torch.Tensor, torch.Tensor]:
    """Maximise ``score`` over actions in [-1, 1]^A for a batch of B states.

    ``score`` maps candidates (B, N, A) to scores (B, N); ``noise`` is
    standard normal of shape (B, iterations, N, A).  Returns the best action
    (B, A) seen over all iterations and its score (B,).
    """
    b, iterations, n, a = noise.shape
    if iterations != cfg.iterations or n != cfg.samples:
        raise ValueError(f"CEM noise has shape {tuple(noise.shape)}; expected (B, {cfg.iterations}, {cfg.samples}, A)")
    mean = noise.new_zeros(b, 1, a)
    std = noise.new_full((b, 1, a), cfg.init_std)
    best_score = noise.new_full((b,), -float("inf"))
    best_action = noise.new_zeros(b, a)
    rows = torch.arange(b, device=noise.device)
    for it in range(iterations):
        cand = (mean + std * noise[:, it]).clamp_(-1.0, 1.0)
        s = score(cand)
        top_s, top_i = s.topk(cfg.elites, dim=1)
        better = top_s[:, 0] > best_score
        best_score = torch.where(better, top_s[:, 0], best_score)
        best_action = torch.where(better.unsqueeze(1), cand[rows, top_i[:, 0]], best_action)
        if it + 1 < iterations:
            elites = cand.gather(1, top_i.unsqueeze(-1).expand(-1, -1, a))
            mean = elites.mean(1, keepdim=True)
            std = elites.std(1, unbiased=False, keepdim=True).clamp_min_(cfg.min_std)
    return best_action, best_score


def active_actions(actions: np.ndarray | torch.Tensor, net: NetConfig):
    """The components the network reads, (B, 6) -> (B, A)."""
    return actions[:, list(net.action_dims)]


def full_actions(active: np.ndarray, net: NetConfig) -> np.ndarray:
    """Environment actions (B, 6): the active components, the rest at ``net.default_action``."""
    out = np.tile(np.asarray(net.default_action, dtype=np.float32), (len(active), 1))
    out[:, list(net.action_dims)] = active
    assert out.shape[1] == ACTION_DIM
    return out
