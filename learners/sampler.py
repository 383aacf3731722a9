"""The transition-sampler contract the learner trains from, and an in-memory sampler.

A sampler is any object with::

    sample(batch_size: int, rng: numpy.random.Generator) -> dict[str, np.ndarray]
    describe() -> dict          # data versions and weights, recorded in checkpoints
    tables() -> list            # optional: the transitions as arrays, for a GPU to hold (learners/cuda_graph.py)

``sample`` returns a batch keyed by ``nsl.keys``: ``OBS_IMAGE`` (B, H, W, 3)
uint8, ``OBS_STATE`` (B, STATE_DIM) float32, ``ACTION`` (B, ACTION_DIM)
float32, ``REWARD`` (B,) float32, ``DONE`` (B,) float32, ``NEXT_OBS_IMAGE``
and ``NEXT_OBS_STATE`` (and ``DISCOUNT`` for n-step transitions).  All
randomness comes from ``rng`` (owned, saved and restored by the trainer), so
a sampler holds no random state of its own.

Mixing sources by weight (the study's 50/50 base and target batches) is the
dataset loader's job: ``nsl.datasets.api.make_sampler([(ref, weight), ...])``
is the one implementation.  :class:`ArraySampler` wraps numpy arrays of a
single source (tests, benchmarks, small experiments).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any, Protocol

import numpy as np

from nsl import keys
from nsl.errors import ConfigError

BATCH_KEYS = (
    keys.OBS_IMAGE,
    keys.OBS_STATE,
    keys.ACTION,
    keys.REWARD,
    keys.DONE,
    keys.NEXT_OBS_IMAGE,
    keys.NEXT_OBS_STATE,
)


class Sampler(Protocol):
    """What :func:`nsl.learners.train` draws its batches from (see the module docstring)."""

    def sample(self, batch_size: int, rng: np.random.Generator) -> dict[str, np.ndarray]: ...

    def describe(self) -> dict[str, Any]: ...


class ArraySampler:
    """Uniform transitions from in-memory arrays; the next observation of transition i is frame ``next_index[i]``.

    Frames are stored once: transition i's observation is frame i and its
    next observation frame ``next_index[i]`` (any frame for a terminal
    transition, whose next state is never used).
    """

    def __init__(
        self,
        images: np.ndarray,
        states: np.ndarray,
        actions: np.ndarray,
        rewards: np.ndarray,
        dones: np.ndarray,
        next_index: np.ndarray,
        name: str = "arrays",
        valid: np.ndarray | None = None,
    ):
        n = len(images)
        if images.ndim != 4 or images.shape[3] != 3 or images.dtype != np.uint8:
            raise ConfigError(f"images must be uint8 (N, H, W, 3); got {images.dtype} {images.shape}")
        if states.ndim != 2:
            raise ConfigError(f"states must be (N, state_dim); got {states.shape}")
        for label, arr, shape in (
            ("states", states, (n, states.shape[1])),
            ("actions", actions, (n, keys.ACTION_DIM)),
            ("rewards", rewards, (n,)),
            ("dones", dones, (n,)),
            ("next_index", next_index, (n,)),
        ):
            if arr.shape != shape:
                raise ConfigError(f"{label} has shape {arr.shape}; expected {shape} to match {n} images")
        if n == 0 or next_index.min() < 0 or next_index.max() >= n:
            raise ConfigError(f"next_index must index the {n} frames (and there must be at least one)")
        self.images = images
        self.states = states.astype(np.float32, copy=False)
        self.actions = actions.astype(np.float32, copy=False)
        self.rewards = rewards.astype(np.float32, copy=False)
        self.dones = dones.astype(np.float32, copy=False)
        self.next_index = next_index.astype(np.int64, copy=False)
        self.indices = np.arange(n) if valid is None else np.flatnonzero(valid)
        if len(self.indices) == 0:
            raise ConfigError("the sampler has no usable transitions")
        self.name = name

    @classmethod
    def from_transitions(cls, batch: dict[str, np.ndarray], name: str = "arrays") -> ArraySampler:
        """From explicit transition arrays keyed by ``nsl.keys`` (next observations stored separately)."""
        missing = [k for k in BATCH_KEYS if k not in batch]
        if missing:
            raise ConfigError(f"transition arrays lack key(s) {missing}; need {list(BATCH_KEYS)}")
        n = len(batch[keys.OBS_IMAGE])
        return cls(
            np.concatenate([batch[keys.OBS_IMAGE], batch[keys.NEXT_OBS_IMAGE]]),
            np.concatenate([batch[keys.OBS_STATE], batch[keys.NEXT_OBS_STATE]]),
            np.concatenate([batch[keys.ACTION], np.zeros_like(batch[keys.ACTION])]),
            np.concatenate([batch[keys.REWARD], np.zeros_like(batch[keys.REWARD])]),
            np.concatenate([batch[keys.DONE], np.ones_like(batch[keys.DONE])]),
            np.concatenate([np.arange(n) + n, np.arange(n) + n]),
            name=name,
            valid=np.arange(2 * n) < n,
        )

    @classmethod
    def from_episodes(cls, episodes: Iterable[Any], name: str = "episodes") -> ArraySampler:
        """From episode records with ``images``, ``states``, ``actions``, ``rewards`` and ``terminated``
        (e.g. ``nsl.collectors.Episode``).  A truncated episode's last transition has no next
        observation, so it is left out."""
        imgs, sts, acts, rews, dones, nxt, valid = [], [], [], [], [], [], []
        start = 0
        for ep in episodes:
            t = len(ep.actions)
            imgs.append(ep.images)
            sts.append(ep.states)
            acts.append(ep.actions)
            rews.append(ep.rewards)
            d = np.zeros(t, np.float32)
            d[-1] = float(ep.terminated)
            dones.append(d)
            nxt.append(start + np.minimum(np.arange(1, t + 1), t - 1))
            v = np.ones(t, bool)
            v[-1] = bool(ep.terminated)
            valid.append(v)
            start += t
        if not imgs:
            raise ConfigError("no episodes given to ArraySampler.from_episodes")
        return cls(
            np.concatenate(imgs),
            np.concatenate(sts),
            np.concatenate(acts),
            np.concatenate(rews),
            np.concatenate(dones),
            np.concatenate(nxt),
            name=name,
            valid=np.concatenate(valid),
        )

    def __len__(self) -> int:
        return len(self.indices)

    def sample(self, batch_size: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        i = self.indices[rng.integers(0, len(self.indices), size=batch_size)]
        j = self.next_index[i]
        return {
            keys.OBS_IMAGE: self.images[i],
            keys.OBS_STATE: self.states[i],
            keys.ACTION: self.actions[i],
            keys.REWARD: self.rewards[i],
            keys.DONE: self.dones[i],
            keys.NEXT_OBS_IMAGE: self.images[j],
            keys.NEXT_OBS_STATE: self.states[j],
        }

    def tables(self) -> list[tuple[dict[str, np.ndarray], float]]:
        """The transitions as arrays (``images`` and the frame indices ``obs`` and ``next`` into them, then the
        per-transition columns), with weight 1: what a GPU copies to sample there."""
        i = self.indices
        j = self.next_index[i]
        table = {
            "images": self.images,
            "obs": i,
            "next": j,
            keys.OBS_STATE: self.states[i],
            keys.NEXT_OBS_STATE: self.states[j],
            keys.ACTION: self.actions[i],
            keys.REWARD: self.rewards[i],
            keys.DONE: self.dones[i],
        }
        return [(table, 1.0)]

    def describe(self) -> dict[str, Any]:
        rewarded = float(self.rewards[self.indices].sum())
        return {
            "sources": [
                {
                    "name": self.name,
                    "kind": "arrays",
                    "transitions": len(self.indices),
                    "rewards": rewarded,
                    "weight": 1.0,
                }
            ]
        }


def synthetic_sampler(n: int = 512, seed: int = 0, image_size: int = 64) -> ArraySampler:
    """Random transitions in episodes of 8 frames (the last one terminal, half of those rewarded): speed probes'
    data, whose values do not change the work of a step."""
    rng = np.random.default_rng(seed)
    ep = np.arange(n) % 8
    return ArraySampler(
        rng.integers(0, 256, (n, image_size, image_size, 3), dtype=np.uint8),
        rng.random((n, len(keys.STATE_NAMES)), dtype=np.float32),
        rng.uniform(-1, 1, (n, len(keys.ACTION_NAMES))).astype(np.float32),
        ((ep == 7) & (rng.random(n) < 0.5)).astype(np.float32),
        (ep == 7).astype(np.float32),
        np.minimum(np.arange(n) + 1, n - 1),
        name="synthetic",
    )
