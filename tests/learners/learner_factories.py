"""Factories for the learner tests: tiny configs and synthetic transitions."""

from __future__ import annotations

import numpy as np

from nsl import keys
from nsl.learners import CemConfig, NetConfig, TrainConfig

TINY_NET = NetConfig(image_size=16, conv_channels=(8, 8), conv_strides=(2, 2), hidden=16)
TINY_CEM = CemConfig(samples=16, elites=4, iterations=2)


def tiny_train(**changes) -> TrainConfig:
    base = dict(steps=20, batch_size=16, cem=TINY_CEM, log_every=5, checkpoint_every=10, lag_period=5)
    return TrainConfig(**{**base, **changes})


def colour_task(n: int, seed: int = 0, size: int = 16) -> dict[str, np.ndarray]:
    """A one-step task: red images succeed iff dx > 0.5, blue images iff dx < -0.5 (any other action fails)."""
    rng = np.random.default_rng(seed)
    red = rng.random(n) < 0.5
    images = rng.integers(0, 40, (n, size, size, 3), dtype=np.uint8)
    images[red, :, :, 0] += 200
    images[~red, :, :, 2] += 200
    actions = rng.uniform(-1, 1, (n, 6)).astype(np.float32)
    success = np.where(red, actions[:, 0] > 0.5, actions[:, 0] < -0.5)
    states = rng.random((n, 6), dtype=np.float32)
    return {
        keys.OBS_IMAGE: images,
        keys.OBS_STATE: states,
        keys.ACTION: actions,
        keys.REWARD: success.astype(np.float32),
        keys.DONE: np.ones(n, np.float32),
        keys.NEXT_OBS_IMAGE: images,
        keys.NEXT_OBS_STATE: states,
    }


def random_transitions(n: int, seed: int = 0, size: int = 16, done_rate: float = 0.3) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {
        keys.OBS_IMAGE: rng.integers(0, 256, (n, size, size, 3), dtype=np.uint8),
        keys.OBS_STATE: rng.random((n, 6), dtype=np.float32),
        keys.ACTION: rng.uniform(-1, 1, (n, 6)).astype(np.float32),
        keys.REWARD: (rng.random(n) < 0.3).astype(np.float32),
        keys.DONE: (rng.random(n) < done_rate).astype(np.float32),
        keys.NEXT_OBS_IMAGE: rng.integers(0, 256, (n, size, size, 3), dtype=np.uint8),
        keys.NEXT_OBS_STATE: rng.random((n, 6), dtype=np.float32),
    }
