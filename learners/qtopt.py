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

With ``TrainConfig.device`` ``cuda`` the same text runs on the GPU
(``learners/device.py``): the step's random draws come from a generator on the
device, terminal transitions are masked rather than indexed out (counting
them would make the host wait for the device), and the metrics stay on the
device until the loop logs them.
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
from .device import generator, resolve_device, to_device
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
        device = resolve_device(cfg.device)
        cuda = device == "cuda"  # capturable: a CUDA graph may replay its step (learners/cuda_graph.py)
        fused = True if cfg.precision == "bf16" or cuda else None  # None: torch's default (the per-tensor loop)
        net = net.to(device)
        params = net.trainable_parameters()
        opt = torch.optim.Adam(params, lr=lr, weight_decay=cfg.weight_decay, fused=fused, capturable=cuda)
        return cls(net, clone_frozen(net), clone_frozen(net), opt, generator(device, cfg.seed))

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
        return dict(zip(METRICS, step_metrics(state, batch, cfg, step).unbind()))  # read when the loop logs


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
    masked: bool | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Clipped double-Q targets (B,) and the next-state values (B,) (0 where ``done``).

    ``gamma`` is a number or a per-transition (B,) discount (n-step batches).
    Terminal transitions need no next-state value.  On the CPU, CEM runs
    only on the others (``noise`` is drawn for the whole batch, keeping the
    draw fixed); on a GPU it runs on all of them and the terminal ones are
    masked, so the host never waits to count them (``masked`` chooses).
    """
    live = done < 0.5
    if masked is None:
        masked = reward.device.type != "cpu"
    if masked:
        value = _next_value(polyak, lagged, next_image, next_state, noise, cem) * live
        return reward + gamma * (1.0 - done) * value, value
    value = torch.zeros_like(reward)
    rows = live.nonzero().squeeze(1)
    if len(rows):
        value[rows] = _next_value(polyak, lagged, next_image[rows], next_state[rows], noise[rows], cem)
    return reward + gamma * (1.0 - done) * value, value


def _next_value(
    polyak: QNetwork,
    lagged: QNetwork,
    next_image: torch.Tensor,
    next_state: torch.Tensor,
    noise: torch.Tensor,
    cem: CemConfig,
) -> torch.Tensor:
    """min(Q_polyak, Q_lagged) at the polyak network's CEM maximum, as probabilities (B,)."""
    x = polyak.input(next_image)  # both target networks read the same input
    ctx = polyak.encode_input(x, next_state)
    best, logit_polyak = cem_maximize(lambda cand: polyak.score(ctx, cand).float(), noise, cem)
    logit_lagged = lagged.score(lagged.encode_input(x, next_state), best.unsqueeze(1)).squeeze(1).float()
    return torch.sigmoid(torch.minimum(logit_polyak, logit_lagged))


@torch.no_grad()
def polyak_update(target: QNetwork, online: QNetwork, polyak: float) -> None:
    """target <- polyak * target + (1 - polyak) * online, for the trainable parameters."""
    pairs = [(t, o) for t, o in zip(target.parameters(), online.parameters()) if o.requires_grad]
    torch._foreach_lerp_([t for t, _ in pairs], [o for _, o in pairs], 1.0 - polyak)


METRICS = (
    "losses/q_loss",
    "losses/conservative",
    "losses/grad_norm",
    "q/mean",
    "q/min",
    "q/max",
    "q/target_mean",
    "q/next_value_mean",
)


def update(learner: Learner, batch: dict[str, torch.Tensor], cfg: TrainConfig, step: int) -> dict[str, float]:
    """One QT-Opt gradient step on ``batch`` (tensors keyed by ``nsl.keys``); returns metrics."""
    return dict(zip(METRICS, step_metrics(learner, batch, cfg, step).tolist()))


def step_metrics(
    learner: Learner, batch: dict[str, torch.Tensor], cfg: TrainConfig, step: int, refresh_lag: bool = True
) -> torch.Tensor:
    """One QT-Opt gradient step; the metrics (``METRICS``) as a float64 tensor on the learner's device, unread.

    ``refresh_lag=False`` leaves the lagged network's refresh to the caller (a captured step, replayed for every
    step number, cannot decide it).
    """
    net, gen = learner.online, learner.generator
    device = gen.device.type  # where the learner lives (cfg.device may still say auto)
    batch = to_device(batch, device)
    image = prepare_images(batch[keys.OBS_IMAGE], cfg.augment_crop, cfg.augment_colour, gen)
    next_image = prepare_images(batch[keys.NEXT_OBS_IMAGE], cfg.augment_crop, cfg.augment_colour, gen)
    action = active_actions(batch[keys.ACTION], net.cfg)
    reward, done = batch[keys.REWARD], batch[keys.DONE]
    noise = noise_from_generator(len(reward), action.shape[1], cfg.cem, gen)

    with torch.no_grad(), autocast(cfg.precision, device):
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
        shape = (len(reward), cfg.conservative_samples, action.shape[1])
        rand = torch.rand(shape, generator=gen, device=gen.device) * 2.0 - 1.0
        with autocast(cfg.precision, device):
            candidates = torch.cat([action.unsqueeze(1), rand], 1)
            all_logits = net.score(net.encode(image, batch[keys.OBS_STATE]), candidates).float()
        logits = all_logits[:, 0]
        rand_logits = all_logits[:, 1:]
        conservative = F.binary_cross_entropy_with_logits(rand_logits, torch.zeros_like(rand_logits))
    else:
        with autocast(cfg.precision, device):
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
    if refresh_lag and (step + 1) % cfg.lag_period == 0:
        refresh_lagged(learner)

    q = torch.sigmoid(logits.detach())
    live = (done < 0.5).float()
    live_mean = (next_value * live).sum() / live.sum().clamp_min(1.0)  # no host sync to count the live ones
    stats = [td_loss.detach(), conservative.detach(), grad_norm, q.mean(), q.min(), q.max(), target.mean(), live_mean]
    return torch.stack(stats).double()


def refresh_lagged(learner: Learner) -> None:
    """The lagged target network becomes a copy of the online one (in place: its tensors keep their storage)."""
    learner.lagged.load_state_dict(learner.online.state_dict())


def batch_to_torch(batch: dict) -> dict[str, torch.Tensor]:
    """numpy arrays from a sampler -> tensors (no copy), rewards and done flags as float32."""
    out = {k: torch.from_numpy(v) for k, v in batch.items()}
    for k in (keys.REWARD, keys.DONE):
        out[k] = out[k].float()
    return out
