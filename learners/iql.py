"""Implicit Q-learning (Kostrikov, Nair and Levine 2022) for the grasping Q-function: the learner ``iql``.

QT-Opt's target maximises over actions with CEM, so offline it bootstraps through actions the data never took.
IQL never evaluates an action outside the data in its targets: a state-value V is fitted to an upper expectile of
the target Q over the data's actions, and Q is fitted to the Bellman backup through V::

    L_V = mean over (s, a) of |tau - 1(u < 0)| u^2,   u = Q_polyak(s, a) - V(s)        (IQL's eq. 5, expectile tau)
    L_Q = mean over (s, a, r, s') of BCE(Q(s, a), r + gamma^k (1 - done) V(s'))        (its eq. 6, in log loss)

Q and V are probabilities of success (sigmoids of logits), as in QT-Opt.  V(s) is a second network of the
Q-network's architecture scoring one fixed action (zero), so a fine-tune starts it from the parent's weights; the
first ``v_warmup`` steps fit V alone.  With n-step batches r is the data's discounted k-step return and gamma^k
the batch's discount, as in QT-Opt.  ``Q_polyak`` is the Polyak average of Q (``TrainConfig.polyak``).

A checkpoint holds Q, and acts as QT-Opt's do, by CEM over Q: IQL's advantage-weighted actor is replaced by the
search the collectors already run, so checkpoints of both learners are the same kind of object and every
evaluation, study table and fine-tuning method applies to both.  IQL has no conservative term (its targets never
query unseen actions), so ``TrainConfig.conservative`` stays 0.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import torch
import torch.nn.functional as F

from nsl import keys
from nsl.errors import ConfigError

from .algorithm import Algorithm
from .augment import prepare_images
from .cem import active_actions
from .config import TrainConfig
from .device import generator, resolve_device, to_device
from .networks import QNetwork, clone_frozen
from .precision import autocast
from .qtopt import polyak_update


@dataclass(frozen=True)
class IQLOptions:
    """IQL's own settings (``nsl train --learner iql:expectile=0.9,v_warmup=0``)."""

    expectile: float = 0.8  # tau: 0.5 fits V to the data's mean Q (SARSA), towards 1 to its best action's
    v_warmup: int = 200  # first steps fitting V alone (a fine-tune's V starts as the parent's Q of the zero action)

    def __post_init__(self) -> None:
        if not 0.5 <= float(self.expectile) < 1.0:
            raise ConfigError(f"iql expectile {self.expectile} must be in [0.5, 1); 0.7-0.9 is usual")
        if int(self.v_warmup) != self.v_warmup or self.v_warmup < 0:
            raise ConfigError(f"iql v_warmup {self.v_warmup} must be a whole number of steps >= 0")


@dataclass
class IQLState:
    """Everything an IQL step changes: Q, its Polyak average, V, their optimisers and the step's generator."""

    online: QNetwork  # Q: what a checkpoint saves
    polyak: QNetwork
    value: QNetwork  # V(s) = sigmoid(value(s, zero action))
    optimizer: torch.optim.Optimizer
    value_optimizer: torch.optim.Optimizer
    generator: torch.Generator

    def set_lr(self, lr: float) -> None:
        for opt in (self.optimizer, self.value_optimizer):
            for group in opt.param_groups:
                group["lr"] = lr

    def state_dict(self) -> dict:
        return {
            "online": self.online.state_dict(),
            "polyak": self.polyak.state_dict(),
            "value": self.value.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "value_optimizer": self.value_optimizer.state_dict(),
            "generator": self.generator.get_state(),
        }

    def load_state_dict(self, state: dict) -> None:
        for name in ("online", "polyak", "value", "optimizer", "value_optimizer"):
            getattr(self, name).load_state_dict(state[name])
        self.generator.set_state(state["generator"])


def expectile_loss(u: torch.Tensor, tau: float) -> torch.Tensor:
    """IQL's asymmetric squared loss: residuals above V weigh ``tau``, below it ``1 - tau``."""
    return (torch.abs(tau - (u < 0).float()) * u.square()).mean()


class IQL(Algorithm):
    """The learner ``iql``."""

    name = "iql"
    Options = IQLOptions

    def create(self, net: QNetwork, lr: float, cfg: TrainConfig, options: IQLOptions) -> IQLState:
        device = resolve_device(cfg.device)
        fused = True if cfg.precision == "bf16" or device == "cuda" else None
        net = net.to(device)
        value = copy.deepcopy(net).train()
        opt = torch.optim.Adam(net.trainable_parameters(), lr=lr, weight_decay=cfg.weight_decay, fused=fused)
        value_opt = torch.optim.Adam(value.trainable_parameters(), lr=lr, weight_decay=cfg.weight_decay, fused=fused)
        return IQLState(net, clone_frozen(net), value, opt, value_opt, generator(device, cfg.seed))

    def update(self, state: IQLState, batch: dict, cfg: TrainConfig, step: int, options: IQLOptions) -> dict:
        q, value, gen = state.online, state.value, state.generator
        device = gen.device.type  # where the learner lives (cfg.device may still say auto)
        batch = to_device(batch, device)
        image = prepare_images(batch[keys.OBS_IMAGE], cfg.augment_crop, cfg.augment_colour, gen)
        next_image = prepare_images(batch[keys.NEXT_OBS_IMAGE], cfg.augment_crop, cfg.augment_colour, gen)
        obs_state, next_state = batch[keys.OBS_STATE], batch[keys.NEXT_OBS_STATE]
        action = active_actions(batch[keys.ACTION], q.cfg)
        zero = torch.zeros_like(action)
        reward, done = batch[keys.REWARD], batch[keys.DONE]
        clip = cfg.grad_clip if cfg.grad_clip > 0 else float("inf")

        # V: the tau-expectile of the target Q over the data's actions.
        with torch.no_grad(), autocast(cfg.precision, device):
            q_data = torch.sigmoid(state.polyak(image, obs_state, action).float())
        with autocast(cfg.precision, device):
            v = torch.sigmoid(value(image, obs_state, zero).float())
        v_loss = expectile_loss(q_data - v, options.expectile)
        state.value_optimizer.zero_grad(set_to_none=True)
        v_loss.backward()
        torch.nn.utils.clip_grad_norm_(value.trainable_parameters(), clip)
        state.value_optimizer.step()

        # Q: the Bellman backup through V of the next state.
        with torch.no_grad(), autocast(cfg.precision, device):
            next_value = torch.sigmoid(value(next_image, next_state, zero).float()) * (1.0 - done)
        target = reward + batch.get(keys.DISCOUNT, cfg.gamma) * next_value
        warm = step < options.v_warmup
        with torch.set_grad_enabled(not warm), autocast(cfg.precision, device):
            logits = q(image, obs_state, action).float()
        q_loss = F.binary_cross_entropy_with_logits(logits, target)
        grad_norm = torch.zeros((), device=logits.device)
        if not warm:
            state.optimizer.zero_grad(set_to_none=True)
            q_loss.backward()
            grad_norm = torch.nn.utils.clip_grad_norm_(q.trainable_parameters(), clip)
            state.optimizer.step()
            polyak_update(state.polyak, q, cfg.target_polyak)

        qs = torch.sigmoid(logits.detach())
        live = (done < 0.5).float()
        stats = torch.stack(
            [
                q_loss.detach(),
                v_loss.detach(),
                grad_norm,
                qs.mean(),
                target.mean(),
                v.detach().mean(),
                (next_value * live).sum() / live.sum().clamp_min(1.0),  # no host sync to count the live ones
            ]
        ).double()
        names = [
            "losses/q_loss",
            "losses/v_loss",
            "losses/grad_norm",
            "q/mean",
            "q/target_mean",
            "v/mean",
            "q/next_value_mean",
        ]
        return dict(zip(names, stats.unbind()))  # read when the loop logs
