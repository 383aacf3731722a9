"""The one helper behind the offline criteria and the diagnostics: per-frame success, masks and returns."""

from __future__ import annotations

import numpy as np

from nsl import keys
from nsl.datasets import api


def _arrays():
    # episode 0: three frames, succeeds at its end; episode 1: two frames, truncated (no done); episode 2: one frame
    return {
        keys.EPISODE_INDEX: np.array([0, 0, 0, 1, 1, 2]),
        keys.SUCCESS: np.array([0, 0, 1, 0, 0, 0]),
        keys.DONE: np.array([0, 0, 1, 0, 0, 1]),
        keys.REWARD: np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0], dtype=np.float32),
    }


def test_labels_masks_and_returns():
    labels = api.frame_labels(_arrays(), gamma=0.5)
    assert labels.success.tolist() == [True, True, True, False, False, False]
    assert labels.following.tolist() == [True, True, False, True, False, False]
    assert labels.known.tolist() == [True, True, True, True, False, True]  # frame 4 was truncated
    assert labels.live.tolist() == [0, 1, 3]  # frames that bootstrap from a next frame
    assert labels.first.tolist() == [True, False, False, True, False, True]
    assert labels.episode_success == {0: True, 1: False, 2: False}
    np.testing.assert_allclose(labels.mc_return, [0.25, 0.5, 1.0, 0.0, 0.0, 0.0])


def test_returns_only_with_a_discount():
    assert api.frame_labels(_arrays()).mc_return is None
