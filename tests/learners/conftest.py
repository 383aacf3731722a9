"""Fixtures for the learner tests: one torch thread, a shared sampler and a trained parent checkpoint."""

from __future__ import annotations

import pytest
import torch
from learner_factories import TINY_NET, random_transitions, tiny_train

from nsl.learners import ArraySampler, train


@pytest.fixture(autouse=True)
def _one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture(scope="session")
def random_sampler() -> ArraySampler:
    return ArraySampler.from_transitions(random_transitions(256), name="random")


@pytest.fixture(scope="session")
def parent_checkpoint(tmp_path_factory, random_sampler):
    """A briefly pre-trained tiny checkpoint (lr 1e-3), shared by the fine-tuning tests."""
    out = tmp_path_factory.mktemp("parent")
    torch.set_num_threads(1)
    return train(tiny_train(lr=1e-3), random_sampler, out, net=TINY_NET, progress=False).checkpoint
