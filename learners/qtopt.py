"""Offline QT-Opt: the Bellman target and one gradient step.

The online network is trained with log loss (binary cross-entropy on the
logit) against the clipped double-Q target of QT-Opt::

    a*     = argmax_a Q_polyak(s', a)                       (CEM)
    target = r + gamma * (1 - done) * min(Q_polyak(s', a*), Q_lagged(s', a*))

With n-step transitions (``TrainConfig.n_step``) r is the discounted return
of up to n data steps and gamma becomes the batch's ``keys.DISCOUNT``,
gamma^k: the data's own actions replace k - 1 of the maximisations.

``Q_polyak`` is a Polyak average of the online weights (updated every step)
and ``Q_lagged`` a copy of the online weights refreshed every
``lag_period`` steps.  Q values are probabilities of success (sigmoids), so a
target is in [0, 1] for rewards in {0, 1} and gamma <= 1.

Offline, CEM's maximum in the target finds actions the data never tried,
whose values nothing corrects, and the optimism spreads backwards through the
episode.  ``TrainConfig.conservative`` (alpha) adds a conservative term in the
spirit of CQL (Kumar et al. 2020), written for a probability-valued Q: uniform
random actions are scored as failures with weight alpha::

    loss += alpha * mean_{s, a ~ U} BCE(logit(s, a), 0)

(CQL's own logsumexp form raises the data actions' values while it lowers the
others'; with a sigmoid Q that inflated every target towards 1 here.)

With ``TrainConfig.precision`` ``bf16`` the network passes (the target's CEM
search and the loss's forward pass) run under CPU bfloat16 autocast; the
logits are taken back to float32 before the sigmoid, the minimum and the log
loss, and the weights and Adam's state stay float32 (``learners/precision.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F

from nsl import keys

from .algorithm import Algorithm, NoOptions
from .augment import prepare_images
from .cem import active_actions, cem_maximize, noise_from_generator
from .config import CemConfig, TrainConfig
from .networks import QNetwork, clone_frozen
from .precision import autocast


@dataclass
class Learner:
    """Everything a gradient step changes: the networks, the optimiser and the step's random generator."""

    online: QNetwork
    polyak: QNetwork
    lagged: QNetwork
    optimizer: torch.optim.Optimizer
    generator: torch.Generator  # augmentation and CEM noise

    @classmethod
    def create(cls, net: QNetwork, lr: float, cfg: TrainConfig) -> Learner:
        """A learner whose Adam starts at ``lr`` (the loop sets each step's rate from ``cfg.lr_at``).

        A ``bf16`` run updates with torch's fused CPU Adam (one kernel over all parameters, several times faster
        than the per-tensor loop); ``fp32`` keeps the default implementation, so its weights stay those of every
        float32 run before the option existed.
        """
        fused = True if cfg.precision == "bf16" else None  # None: torch's default (the per-tensor loop)
        opt = torch.optim.Adam(net.trainable_parameters(), lr=lr, weight_decay=cfg.weight_decay, fused=fused)
        gen = torch.Generator().manual_seed(cfg.seed)
        return cls(net, clone_frozen(net), clone_frozen(net), opt, gen)

    def set_lr(self, lr: float) -> None:
        for group in self.optimizer.param_groups:
            group["lr"] = lr

    def state_dict(self) -> dict:
        return {
            "online": self.online.state_dict(),
            "polyak": self.polyak.state_dict(),
            "lagged": self.lagged.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "generator": self.generator.get_state(),
        }

    def load_state_dict(self, state: dict) -> None:
        self.online.load_state_dict(state["online"])
        self.polyak.load_state_dict(state["polyak"])
        self.lagged.load_state_dict(state["lagged"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.generator.set_state(state["generator"])


class QTOpt(Algorithm):
    """The learner ``qtopt``: :class:`Learner` and :func:`update` behind the learner interface."""

    name = "qtopt"
    conservative = True

    def create(self, net: QNetwork, lr: float, cfg: TrainConfig, options: NoOptions) -> Learner:
        return Learner.create(net, lr, cfg)

    def update(self, state: Learner, batch: dict, cfg: TrainConfig, step: int, options: NoOptions) -> dict:
        return update(state, batch, cfg, step)


def bellman_target(
    polyak: QNetwork,
    lagged: QNetwork,
    next_image: torch.Tensor,
    next_state: torch.Tensor,
    reward: torch.Tensor,
    done: torch.Tensor,
    gamma: float | torch.Tensor,
    cem: CemConfig,
    noise: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Clipped double-Q targets (B,) and the next-state values (B,) (0 where ``done``).

    ``gamma`` is a number or a per-transition (B,) discount (n-step batches).
    Terminal transitions need no next-state value, so CEM runs only on the
    others (``noise`` is drawn for the whole batch, keeping the draw fixed).
    """
    value = torch.zeros_like(reward)
    live = (done < 0.5).nonzero().squeeze(1)
    if len(live):
        x, st = polyak.input(next_image[live]), next_state[live]  # both target networks read the same input
        ctx = polyak.encode_input(x, st)
        best, logit_polyak = cem_maximize(lambda cand: polyak.score(ctx, cand).float(), noise[live], cem)
        logit_lagged = lagged.score(lagged.encode_input(x, st), best.unsqueeze(1)).squeeze(1).float()
        value[live] = torch.sigmoid(torch.minimum(logit_polyak, logit_lagged))
    return reward + gamma * (1.0 - done) * value, value


@torch.no_grad()
def polyak_update(target: QNetwork, online: QNetwork, polyak: float) -> None:
    """target <- polyak * target + (1 - polyak) * online, for the trainable parameters."""
    pairs = [(t, o) for t, o in zip(target.parameters(), online.parameters()) if o.requires_grad]
    torch._foreach_lerp_([t for t, _ in pairs], [o for _, o in pairs], 1.0 - polyak)


def update(learner: Learner, batch: dict[str, torch.Tensor], cfg: TrainConfig, step: int) -> dict[str, float]:
    """One QT-Opt gradient step on ``batch`` (tensors keyed by ``nsl.keys``); returns metrics."""
    net, gen = learner.online, learner.generator
    image = prepare_images(batch[keys.OBS_IMAGE], cfg.augment_crop, cfg.augment_colour, gen)
    next_image = prepare_images(batch[keys.NEXT_OBS_IMAGE], cfg.augment_crop, cfg.augment_colour, gen)
    action = active_actions(batch[keys.ACTION], net.cfg)
    reward, done = batch[keys.REWARD], batch[keys.DONE]
    noise = noise_from_generator(len(reward), action.shape[1], cfg.cem, gen)

    with torch.no_grad(), autocast(cfg.precision):
        target, next_value = bellman_target(
            learner.polyak,
            learner.lagged,
            next_image,
            batch[keys.NEXT_OBS_STATE],
            reward,
            done,
            batch.get(keys.DISCOUNT, cfg.gamma),
            cfg.cem,
            noise,
        )

    alpha = cfg.conservative or 0.0  # None (unresolved, outside train()) is plain QT-Opt
    if alpha > 0:
        # The data's action first, then uniform random candidates; one trunk pass for all of them.
        rand = torch.rand(len(reward), cfg.conservative_samples, action.shape[1], generator=gen) * 2.0 - 1.0
        with autocast(cfg.precision):
            candidates = torch.cat([action.unsqueeze(1), rand], 1)
            all_logits = net.score(net.encode(image, batch[keys.OBS_STATE]), candidates).float()
        logits = all_logits[:, 0]
        rand_logits = all_logits[:, 1:]
        conservative = F.binary_cross_entropy_with_logits(rand_logits, torch.zeros_like(rand_logits))
    else:
        with autocast(cfg.precision):
            logits = net(image, batch[keys.OBS_STATE], action).float()
        conservative = logits.new_zeros(())
    td_loss = F.binary_cross_entropy_with_logits(logits, target)
    loss = td_loss + alpha * conservative
    learner.optimizer.zero_grad(set_to_none=True)
    loss.backward()
    params = net.trainable_parameters()
    grad_norm = torch.nn.utils.clip_grad_norm_(params, cfg.grad_clip if cfg.grad_clip > 0 else float("inf"))
    learner.optimizer.step()

    polyak_update(learner.polyak, net, cfg.target_polyak)
    if (step + 1) % cfg.lag_period == 0:
        learner.lagged.load_state_dict(net.state_dict())

    q = torch.sigmoid(logits.detach())
    live = done < 0.5
    stats = torch.stack(
        [
            td_loss.detach(),
            conservative.detach(),
            grad_norm,
            q.mean(),
            q.min(),
            q.max(),
            target.mean(),
            next_value[live].mean() if live.any() else next_value.new_tensor(0.0),
        ]
    ).tolist()
    names = [
        "losses/q_loss",
        "losses/conservative",
        "losses/grad_norm",
        "q/mean",
        "q/min",
        "q/max",
        "q/target_mean",
        "q/next_value_mean",
    ]
    return dict(zip(names, stats))


def batch_to_torch(batch: dict) -> dict[str, torch.Tensor]:
    """numpy arrays from a sampler -> tensors (no copy), rewards and done flags as float32."""
    out = {k: torch.from_numpy(v) for k, v in batch.items()}
    for k in (keys.REWARD, keys.DONE):
        out[k] = out[k].float()
    return out
