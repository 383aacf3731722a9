"""The CEM policy: a Q-network acting greedily through CEM, optionally with exploration.

It follows the collectors' policy interface::

    actions = policy(obs, rngs=rngs)      # obs["image"] (B, H, W, 3) uint8, obs["state"] (B, 2)

and returns (B, 6) float32 environment actions.  Two kinds of exploration can
be added: ``action_noise`` perturbs every greedy action with Gaussian noise
(local exploration, near what the policy would do), and ``epsilon`` replaces
an action by a uniformly random one.  Episode i's CEM noise and
exploration draws come from ``rngs[i]`` alone, and its network passes are
computed for its state alone (batch of one), so its actions do not depend on
which episodes share its batch, nor on the batch size or the thread count: a
batched convolution or matrix product rounds differently with the batch
size and the threads (Q-values change in the seventh digit), which could
flip CEM's choice between two near-equal candidates.

On a GPU (``device="cuda"``) one state at a time would leave the device idle
(a search costs the same 1.6 ms for 1 state or 64), so the policy acts in
batches there: the batch's states are encoded together and one CEM call
searches all of them.  Each episode's noise still comes from its own
generator, so its episodes are reproducible for a given seed, device and
batch size (``nsl eval --num-envs``); ``batched=True`` asks for the same on
the CPU.  For worker processes,
pass ``functools.partial(load_policy, checkpoint_dir)``: it pickles as a path
and loads the checkpoint inside the worker.  :meth:`CEMPolicy.describe`
records the checkpoint by its content id, never by its path, because it goes
into the hashed metadata of the datasets the policy collects.

:class:`LeRobotActing` gives a loaded policy LeRobot's calling convention as
well: ``select_action({"observation.image": (B, 3, H, W) float in [0, 1],
"observation.state": (B, 6)})`` returns a (B, 6) action tensor, and ``reset()``
starts its random draws over (what ``nsl.load_policy`` returns).
"""

from __future__ import annotations

import functools
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from nsl import keys
from nsl.errors import ConfigError

from .augment import to_float
from .cem import cem_maximize, full_actions, noise_from_rngs
from .config import CemConfig, TrainConfig
from .device import resolve_device
from .networks import QNetwork
from .precision import autocast, resolve_precision


class CEMPolicy:
    """Greedy CEM over a Q-network.

    ``action_noise`` adds Gaussian noise of that standard deviation (in action units, clipped to [-1, 1]) to every
    greedy action; then, with probability ``epsilon`` per step, a uniform random action replaces it.  ``device``
    is where the network runs; ``batched`` (default: on a GPU only) searches the batch's states in one call.
    """

    needs_privileged = False

    def __init__(
        self,
        net: QNetwork,
        cem: CemConfig | None = None,
        epsilon: float = 0.0,
        name: str = "cem",
        info: dict[str, Any] | None = None,
        action_noise: float = 0.0,
        precision: str = "fp32",
        device: str = "cpu",
        batched: bool | None = None,
    ):
        if not 0.0 <= epsilon <= 1.0:
            raise ConfigError(f"epsilon {epsilon!r} is out of range; use 0..1 (e.g. 0.1 for exploration)")
        if not 0.0 <= action_noise <= 2.0:
            raise ConfigError(
                f"action_noise {action_noise!r} is out of range; use a standard deviation in 0..2 "
                "action units (e.g. 0.3)"
            )
        self.device = resolve_device(device)
        self.batched = self.device != "cpu" if batched is None else bool(batched)
        self.net = net.to(self.device).eval()
        self.cem = cem or CemConfig()
        self.epsilon = float(epsilon)
        self.action_noise = float(action_noise)
        self.name = name
        self.info = dict(info or {})
        self.precision = resolve_precision(precision, self.device)

    def q_values(self, obs: dict[str, np.ndarray], actions: np.ndarray) -> np.ndarray:
        """P(success) (B,) of environment actions (B, 6) in states ``obs``."""
        image, state = self._inputs(obs)
        with torch.inference_mode(), autocast(self.precision, self.device):
            act = torch.from_numpy(np.asarray(actions, np.float32)[:, list(self.net.cfg.action_dims)]).to(self.device)
            return torch.sigmoid(self.net(image, state, act).float()).cpu().numpy()

    def _inputs(self, obs: dict[str, np.ndarray]) -> tuple[torch.Tensor, torch.Tensor]:
        image = np.asarray(obs["image"])
        n = self.net.cfg.image_size
        if image.dtype != np.uint8 or image.ndim != 4 or image.shape[1:] != (n, n, 3):
            raise ConfigError(
                f"policy {self.name}: images must be uint8 (B, {n}, {n}, 3); got {image.dtype} {image.shape}"
            )
        pixels, state = torch.from_numpy(image), torch.from_numpy(np.asarray(obs["state"], np.float32))
        return to_float(pixels.to(self.device)), state.to(self.device)

    def greedy(self, obs: dict[str, np.ndarray], rngs: list[np.random.Generator]) -> tuple[np.ndarray, np.ndarray]:
        """CEM's best active actions (B, A) and their logits (B,); state i uses ``rngs[i]`` only.

        Unbatched (the CPU's default), each state is encoded and searched alone,
        so its result is the same bits whatever the other states of the batch,
        the batch size or torch's thread count: every kernel sees the same
        shapes and the same inputs.  Batched, one search covers them all.
        """
        image, state = self._inputs(obs)
        if len(rngs) != len(image):
            raise ConfigError(f"policy {self.name}: got {len(rngs)} random generators for {len(image)} observations")
        dims = len(self.net.cfg.action_dims)
        noise = noise_from_rngs(rngs, dims, self.cem).to(self.device)
        if self.batched:
            with torch.inference_mode(), autocast(self.precision, self.device):
                ctx = self.net.encode(image, state)
                b, s = cem_maximize(functools.partial(self._score, ctx), noise, self.cem)
            return b.cpu().numpy(), s.cpu().numpy()
        best, logits = np.zeros((len(image), dims), np.float32), np.zeros(len(image), np.float32)
        with torch.inference_mode(), autocast(self.precision, self.device):
            for i in range(len(image)):
                ctx = self.net.encode(image[i : i + 1], state[i : i + 1])
                b, s = cem_maximize(functools.partial(self._score, ctx), noise[i : i + 1], self.cem)
                best[i], logits[i] = b[0].cpu().numpy(), s[0].item()
        return best, logits

    def _score(self, ctx: list[dict], candidates: torch.Tensor) -> torch.Tensor:
        """Float32 logits of ``candidates`` (whatever precision the head computed them in)."""
        return self.net.score(ctx, candidates).float()

    def __call__(
        self, obs: dict[str, np.ndarray], *, rngs: list[np.random.Generator], privileged: list[dict] | None = None
    ) -> np.ndarray:
        active, _ = self.greedy(obs, rngs)
        dims = len(self.net.cfg.action_dims)
        if self.action_noise > 0:
            for i, rng in enumerate(rngs):
                active[i] = np.clip(active[i] + rng.normal(0.0, self.action_noise, dims), -1.0, 1.0)
        if self.epsilon > 0:
            for i, rng in enumerate(rngs):
                explore, random_action = rng.random() < self.epsilon, rng.uniform(-1.0, 1.0, dims)
                if explore:
                    active[i] = random_action
        return full_actions(active, self.net.cfg)

    def describe(self) -> dict[str, Any]:
        noise: dict[str, Any] = {"action_noise": self.action_noise} if self.action_noise > 0 else {}
        if self.precision != "fp32":  # absent at their defaults: the hashes of datasets made before them hold
            noise["precision"] = self.precision
        if self.device != "cpu":
            noise["device"] = self.device
        if self.batched:
            noise["batched"] = True  # its actions depend on the batch size (nsl collect --num-envs)
        return {
            "policy": "cem",
            "name": self.name,
            "cem": self.cem.to_dict(),
            "epsilon": self.epsilon,
            **noise,
            **self.info,
        }


def load_policy(
    checkpoint_dir: str | Path,
    epsilon: float = 0.0,
    action_noise: float = 0.0,
    precision: str = "fp32",
    device: str = "cpu",
    **cem_overrides: Any,
) -> CEMPolicy:
    """The policy of a checkpoint folder (its learner's; a :class:`CEMPolicy` for the built-in ones); CEM settings
    default to the checkpoint's training ones.

    ``precision`` is the precision it acts in (``fp32``, ``bf16`` or ``auto``) and ``device`` where (``cpu``,
    ``cuda`` or ``auto``), whatever it was trained in and on.
    """
    from .checkpoint import checkpoint_id, load_checkpoint  # here: acting alone needs no checkpoint files (a GPU
    from .registry import find_learner  # machine with torch only runs nsl bench eval --device cuda)

    ckpt = load_checkpoint(Path(checkpoint_dir))
    training = TrainConfig.from_dict(ckpt.config["training"])
    cem = training.cem
    unknown = sorted(set(cem_overrides) - set(cem.to_dict()))
    if unknown:
        raise ConfigError(f"unknown CEM setting(s) {unknown}; known: {sorted(cem.to_dict())}")
    cem = replace(cem, **cem_overrides)
    path = Path(checkpoint_dir)
    # The content id, not the path: a dataset's metadata (and so its version hash) holds this description.
    info = {"checkpoint_id": checkpoint_id(path), "step": ckpt.step}
    algo, _ = find_learner(training.learner)  # how its learner acts (None: CEM over Q, the built-in learners')
    kwargs: dict[str, Any] = {
        "epsilon": epsilon,
        "name": f"ckpt:{path.name}",
        "info": info,
        "action_noise": action_noise,
        "precision": precision,
    }
    if device != "cpu":
        kwargs["device"] = device  # only when asked: a plugin learner's own policy may not take it
    return acting_policy(algo, ckpt.net, cem, **kwargs)


def acting_policy(algo: Any, net: QNetwork, cem: CemConfig, **kwargs: Any) -> CEMPolicy:
    """How a network trained by ``algo`` (an :class:`~nsl.learners.Algorithm`) acts: the learner's own policy,
    else CEM over its Q-function (what the built-in learners do).  ``kwargs`` go to the policy (name, info,
    epsilon, precision, ...)."""
    return algo.policy(net, cem, **kwargs) or CEMPolicy(net, cem, **kwargs)


class LeRobotActing:
    """A policy that acts both as nsl calls it, ``policy(obs, rngs=...)``, and as LeRobot's policies are called,
    ``select_action(batch)``: a dict of tensors (``observation.image`` (B, 3, H, W) float in [0, 1] or uint8
    (B, H, W, 3), ``observation.state`` (B, 6)) in, a (B, 6) float32 action tensor out.

    ``select_action`` draws each row's CEM and exploration noise from a generator seeded with ``seed``;
    ``reset()`` (which LeRobot calls at each episode's start) seeds it again.  Other attributes are the
    wrapped policy's (``describe()``, ``q_values()``, ``name``, ...).
    """

    def __init__(self, policy: Any, seed: int = 0):
        self.policy = policy
        self.seed = seed
        self._rng = np.random.default_rng(seed)

    def __call__(self, obs: dict[str, np.ndarray], **kwargs: Any) -> np.ndarray:
        return self.policy(obs, **kwargs)

    def __getattr__(self, name: str) -> Any:
        if name == "policy":  # not set yet (e.g. while unpickling): no recursion
            raise AttributeError(name)
        return getattr(self.policy, name)

    def reset(self) -> None:
        self._rng = np.random.default_rng(self.seed)

    def select_action(self, batch: dict[str, Any]) -> torch.Tensor:
        missing = [k for k in (keys.OBS_IMAGE, keys.OBS_STATE) if k not in batch]
        if missing:
            raise ConfigError(
                f"select_action needs {keys.OBS_IMAGE!r} and {keys.OBS_STATE!r}; the batch lacks {missing} "
                "(lerobot.envs.utils.preprocess_observation makes them from GraspEnv(obs_type='pixels_agent_pos'))"
            )
        image = torch.as_tensor(batch[keys.OBS_IMAGE]).detach().cpu()
        state = torch.as_tensor(batch[keys.OBS_STATE]).detach().cpu()
        if image.ndim == 3:  # one observation, unbatched
            image, state = image.unsqueeze(0), state.reshape(1, -1)
        if image.dtype != torch.uint8:  # LeRobot's layout: channels first, in [0, 1]
            image = image.permute(0, 2, 3, 1).mul(255.0).round().clamp(0, 255).to(torch.uint8)
        obs = {"image": image.numpy(), "state": state.float().numpy()}
        rngs = self._rng.spawn(len(image))
        return torch.from_numpy(np.asarray(self.policy(obs, rngs=rngs), np.float32))
