"""Factories for dataset tests: synthetic episodes with traceable pixels, real collections, LeRobot offline."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pytest


@dataclass(frozen=True)
class SynthEpisode:
    """An episode record shaped like ``nsl.collectors.Episode``; pixel (0, 0) encodes (episode, frame)."""

    index: int
    images: np.ndarray
    states: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    terminated: bool
    truncated: bool
    success: bool
    info: dict = field(default_factory=dict)


def synth_episode(
    index: int,
    length: int,
    *,
    truncated: bool = False,
    success: bool = False,
    size: int = 16,
    state_offset: float = 0.0,
) -> SynthEpisode:
    rng = np.random.default_rng(index)
    images = rng.integers(0, 256, (length, size, size, 3), dtype=np.uint8)
    images[:, 0, 0, 0] = index
    images[:, 0, 0, 1] = np.arange(length)
    states = np.zeros((length, 6), np.float32)
    states[:, 0], states[:, 1], states[:, 5] = state_offset, np.arange(length) / 10.0, 1.0
    actions = rng.uniform(-1, 1, (length, 6)).astype(np.float32)
    rewards = np.zeros(length, np.float32)
    if success and not truncated:
        rewards[-1] = 1.0
    return SynthEpisode(
        index,
        images,
        states,
        actions,
        rewards,
        terminated=not truncated,
        truncated=truncated,
        success=success and not truncated,
    )


SYNTH_SPEC = {
    "env": {"shift": "synthetic", "image_size": 16},
    "policy": {"policy": "none"},
    "policy_ref": "none",
    "seed": 0,
}


@pytest.fixture
def synth():
    """``synth(index, length, truncated=False, success=False)``: one synthetic episode record."""
    return synth_episode


@pytest.fixture
def make_synth():
    """``make_synth(name, lengths, truncated=set(), successes=set(), ...)`` writes a version, returns it."""
    from nsl.datasets import api

    def make(
        name: str,
        lengths: list[int],
        truncated=(),
        successes=(),
        start: int = 0,
        episodes_per_file: int = 3,
        state_offset: float = 0.0,
        spec: dict | None = None,
    ):
        eps = [
            synth_episode(
                start + i,
                n,
                truncated=(start + i) in truncated,
                success=(start + i) in successes,
                state_offset=state_offset,
            )
            for i, n in enumerate(lengths)
        ]
        return api.write_dataset(name, eps, spec or SYNTH_SPEC, 16, len(eps), episodes_per_file=episodes_per_file)

    return make


@pytest.fixture
def lerobot_offline(monkeypatch, tmp_path):
    """LeRobot/HF datasets with no network and a private Arrow cache; returns ``LeRobotDataset``."""
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    import datasets.config
    import huggingface_hub.constants

    monkeypatch.setattr(huggingface_hub.constants, "HF_HUB_OFFLINE", True)
    monkeypatch.setattr(datasets.config, "HF_DATASETS_CACHE", tmp_path / "hf_datasets_cache")
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    return LeRobotDataset
