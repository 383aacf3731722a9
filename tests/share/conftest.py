"""Fixtures for sharing: a publishing workspace, a fake Hub, LeRobot offline (the S3 server is in tests/conftest.py)."""

from __future__ import annotations

from pathlib import Path

import pytest
from fake_hub import FakeHfApi, FakeHub

from tests.conftest import run_cli
from tests.datasets.conftest import SYNTH_SPEC, synth_episode

TINY_NET = ["--net", "image_size=16", "--net", "conv_channels=8,8", "--net", "conv_strides=2,2", "--net", "hidden=16"]


def write_synth(name: str, lengths: list[int], start: int = 0):
    """A real nsl dataset version of synthetic episodes (16x16 frames, two episodes per data file)."""
    from nsl.datasets import api

    eps = [synth_episode(start + i, n, success=(start + i) % 3 == 0) for i, n in enumerate(lengths)]
    return api.write_dataset(name, eps, SYNTH_SPEC, 16, len(eps), episodes_per_file=2)


@pytest.fixture(scope="module")
def publisher_home(tmp_path_factory):
    return tmp_path_factory.mktemp("publisher")


@pytest.fixture
def publisher(publisher_home, monkeypatch):
    """A workspace with dataset grasp-syn (v1, v2), a tiny pre-trained checkpoint and one fine-tuned from it.

    Built once per module through the real CLI; each test starts in it (NSL_HOME points there).
    """
    monkeypatch.setenv("NSL_HOME", str(publisher_home))
    if not (publisher_home / "runs" / "ft-syn").exists():
        from nsl.catalog import Catalog

        write_synth("grasp-syn", [3, 4, 5, 3, 4])
        write_synth("base-syn", [4, 3, 4, 5])
        assert (
            run_cli("train", "--data", "base-syn", "--steps", "2", "--batch-size", "8", "--name", "base-syn", *TINY_NET)
            == 0
        )
        assert (
            run_cli(
                "train",
                "--data",
                "base-syn=0.5",
                "--data",
                "grasp-syn=0.5",
                "--init",
                "ckpt:base-syn",
                "--steps",
                "2",
                "--batch-size",
                "8",
                "--name",
                "ft-syn",
            )
            == 0
        )
        with Catalog() as cat:
            cat.add_evaluation("ckpt:ft-syn", "synthetic", episodes=20, successes=9, seed=5)
        write_synth("grasp-syn", [2, 3], start=5)  # v2 appends two episodes
    return publisher_home


@pytest.fixture
def workspace_b(tmp_path_factory, monkeypatch):
    """Switch to a new, empty workspace (the lab that pulls); returns a function doing it."""
    home = tmp_path_factory.mktemp("puller")

    def enter() -> Path:
        monkeypatch.setenv("NSL_HOME", str(home))
        return home

    return enter


# ---------------------------------------------------------------------- Hub
@pytest.fixture
def hub(monkeypatch):
    """A fake Hub behind ``HfApi``, ``hf_hub_download`` and ``snapshot_download`` (for nsl and lerobot)."""
    import lerobot.datasets.lerobot_dataset as lerobot_dataset
    import lerobot.datasets.utils as lerobot_utils

    import nsl.share.hub as nsl_hub

    fake = FakeHub()
    monkeypatch.setattr(nsl_hub, "HfApi", lambda *a, **k: FakeHfApi(fake))
    monkeypatch.setattr(nsl_hub, "hf_hub_download", fake.download)
    monkeypatch.setattr(lerobot_utils, "HfApi", lambda *a, **k: FakeHfApi(fake))
    monkeypatch.setattr(lerobot_dataset, "snapshot_download", fake.snapshot)
    monkeypatch.setenv("HF_HUB_OFFLINE", "0")
    return fake


@pytest.fixture
def lerobot(monkeypatch, tmp_path):
    """LeRobot's ``LeRobotDataset`` with a private Arrow cache (and no real network: the Hub is faked)."""
    import datasets.config

    monkeypatch.setattr(datasets.config, "HF_DATASETS_CACHE", tmp_path / "hf_datasets_cache")
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    return LeRobotDataset
