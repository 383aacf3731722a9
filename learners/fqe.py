"""Fitted Q evaluation (FQE): the success rate of a fixed policy, estimated from logged transitions alone.

Le, Voloshin and Yue (2019); Paine et al. (2020) found it the most reliable offline estimate for choosing
among policies, and d3rlpy ships it.  Given held-out transitions ``(s, a, r, s', done)``, the evaluated
policy's actions ``pi(s')`` at the next states and ``pi(s0)`` at the episodes' first states, FQE repeats::

    y       = r + gamma * (1 - done) * Q_k(s', pi(s'))       targets from the current fit, held fixed
    Q_k+1   = a few Adam steps of cross-entropy(Q(s, a), y)  from Q_k

and estimates the policy's value as ``mean Q_K(s0, pi(s0))``.  With nsl's reward (1 at the end of an
episode whose grasp lifts an object, else 0) and ``gamma = 1``, Q is the probability of success, so a
Q-function with a sigmoid output and the cross-entropy against soft targets fits it as QT-Opt's own loss
does; ``iterations`` at least the horizon (8 steps with auto-descent) lets the backups reach the start.

:func:`fitted_q_evaluation` is the algorithm over any logits function; :func:`network_fqe` fits the head of
a checkpoint's Q-network (its trunk frozen: the checkpoint's own features, encoded once) to its CEM policy.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass

import numpy as np
import torch
import torch.nn.functional as F

from nsl.errors import ConfigError

# which(kind, rows) -> logits: kind "data" is Q(s, a) of transitions `rows`, "next" Q(s', pi(s')) of the same rows,
# "initial" Q(s0, pi(s0)) of initial states `rows` (None: all of them).
LogitsFn = Callable[[str, "torch.Tensor | None"], torch.Tensor]


@dataclass(frozen=True)
class FQEConfig:
    """How FQE fits (``nsl train --criterion fqe`` uses these defaults)."""

    iterations: int = 10  # Bellman backups; at least the horizon (8) so values reach the first step
    steps: int = 30  # Adam steps fitting each backup's targets
    lr: float = 1e-3
    gamma: float = 1.0  # undiscounted: with a 0/1 reward at the end, the value is the probability of success
    batch_size: int = 0  # transitions per step; 0: all of them
    seed: int = 0  # the minibatches' draw

    def __post_init__(self) -> None:
        if self.iterations < 1 or self.steps < 1:
            raise ConfigError(f"FQE iterations {self.iterations} and steps {self.steps} must be at least 1")
        if not 0.0 < self.gamma <= 1.0:
            raise ConfigError(f"FQE gamma {self.gamma} must be in (0, 1]")
        if self.lr <= 0 or self.batch_size < 0:
            raise ConfigError(f"FQE lr {self.lr} must be positive and batch_size {self.batch_size} >= 0")

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class FQEResult:
    value: float  # the estimated success rate: mean Q_K(s0, pi(s0))
    values: tuple[float, ...]  # the same estimate after each iteration
    loss: float  # the last fit's cross-entropy


def fitted_q_evaluation(
    logits: LogitsFn,
    parameters: Sequence[torch.nn.Parameter],
    reward: np.ndarray,
    done: np.ndarray,
    config: FQEConfig = FQEConfig(),
) -> FQEResult:
    """FQE over ``logits`` (see :data:`LogitsFn`), fitting ``parameters``; ``reward`` and ``done`` per transition.

    Rewards are in [0, 1] with at most one 1 per episode (targets are clipped to [0, 1]).  A transition whose
    episode was truncated after it has no known target: leave it out of the data.
    """
    r = torch.as_tensor(np.asarray(reward, np.float32))
    not_done = 1.0 - torch.as_tensor(np.asarray(done, np.float32))
    n = len(r)
    if n == 0 or len(not_done) != n:
        raise ConfigError(f"FQE needs one reward and one done flag per transition; got {n} and {len(not_done)}")
    params = list(parameters)
    if not params:
        raise ConfigError("FQE got no parameters to fit")
    opt = torch.optim.Adam(params, lr=config.lr)
    gen = torch.Generator().manual_seed(config.seed)
    values, loss = [], float("nan")
    for _ in range(config.iterations):
        with torch.no_grad():
            target = (r + config.gamma * not_done * torch.sigmoid(logits("next", None))).clamp(0.0, 1.0)
        for _ in range(config.steps):
            rows = None if not config.batch_size or config.batch_size >= n else torch.randperm(n, generator=gen)
            rows = rows if rows is None else rows[: config.batch_size]
            y = target if rows is None else target[rows]
            fit = F.binary_cross_entropy_with_logits(logits("data", rows), y)
            opt.zero_grad(set_to_none=True)
            fit.backward()
            opt.step()
            loss = float(fit.detach())
        with torch.no_grad():
            values.append(float(torch.sigmoid(logits("initial", None)).mean()))
    return FQEResult(values[-1], tuple(values), loss)


def _rows(caches: list[dict], rows: torch.Tensor | None) -> list[dict]:
    if rows is None:
        return caches
    return [
        {k: ([t[rows] for t in v] if isinstance(v, list) else v[rows]) for k, v in cache.items()} for cache in caches
    ]


def network_fqe(
    net,
    data: tuple[dict[str, np.ndarray], np.ndarray],
    next_data: tuple[dict[str, np.ndarray], np.ndarray],
    initial: tuple[dict[str, np.ndarray], np.ndarray],
    reward: np.ndarray,
    done: np.ndarray,
    config: FQEConfig = FQEConfig(),
) -> FQEResult:
    """FQE of a checkpoint's CEM policy with the function class of its own Q-network: the trunk frozen (the
    checkpoint's features, encoded once), the last column's head fitted, starting from the checkpoint's.

    ``data``, ``next_data`` and ``initial`` are ``(obs, actions)``: the held-out transitions' states and
    actions, their next states with the policy's actions there, and the episodes' first states with the
    policy's actions; ``obs`` holds uint8 images (B, H, W, 3) and states; actions are environment actions
    (B, 6) or the network's active dimensions (B, A).
    """
    from .augment import to_float
    from .networks import is_head_parameter

    fitted = copy.deepcopy(net).float().eval()
    fitted.requires_grad_(False)
    last = len(fitted.columns) - 1
    head = [
        p for name, p in fitted.named_parameters() if name.startswith(f"columns.{last}.") and is_head_parameter(name)
    ]
    for p in head:
        p.requires_grad_(True)
    dims = list(net.cfg.action_dims)

    def encode(obs: dict[str, np.ndarray], actions: np.ndarray) -> tuple[list[dict], torch.Tensor]:
        a = np.asarray(actions, np.float32)
        a = a[:, dims] if a.shape[1] != len(dims) else a
        image = to_float(torch.from_numpy(np.asarray(obs["image"])))
        state = torch.from_numpy(np.asarray(obs["state"], np.float32))
        with torch.no_grad():
            caches = [
                {k: (v.detach() if torch.is_tensor(v) else [t.detach() for t in v]) for k, v in c.items()}
                for c in fitted.encode(image, state)
            ]
        return caches, torch.from_numpy(a)

    encoded = {"data": encode(*data), "next": encode(*next_data), "initial": encode(*initial)}

    def logits(kind: str, rows: torch.Tensor | None) -> torch.Tensor:
        caches, actions = encoded[kind]
        act = actions if rows is None else actions[rows]
        return fitted.score(_rows(caches, rows), act.unsqueeze(1)).squeeze(1)

    return fitted_q_evaluation(logits, head, reward, done, config)


__all__ = ["FQEConfig", "FQEResult", "fitted_q_evaluation", "network_fqe"]
