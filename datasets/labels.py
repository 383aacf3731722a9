"""Per-frame labels of logged episodes: episode success, next-frame masks and Monte-Carlo returns.

The offline criteria (SoftOPC, AUC, TD error) and the diagnostics all read the
same four facts from a dataset's frames, in episode order:

* ``success[i]``: frame ``i``'s episode ended in a grasp (any frame flagged);
* ``following[i]``: frame ``i + 1`` is frame ``i``'s next observation (same episode);
* ``known[i]``: frame ``i`` has a known one-step target (terminal, or a next frame
  follows); the last frame of a truncated episode has none;
* ``mc_return[i]``: the discounted return ``G_i = r_i + gamma G_{i+1}`` within the episode.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from nsl import keys


@dataclass(frozen=True)
class FrameLabels:
    """The labels of every frame of some episodes (arrays of one length, in frame order)."""

    episode: np.ndarray  # episode index of each frame
    success: np.ndarray  # bool: the frame's episode succeeded
    following: np.ndarray  # bool: the next frame is this frame's next observation
    done: np.ndarray  # bool: the episode ended at this frame
    reward: np.ndarray  # float64
    mc_return: np.ndarray | None  # float64; None unless a discount was given

    @property
    def known(self) -> np.ndarray:
        """Frames with a known one-step target: terminal, or a next frame follows."""
        return self.done | self.following

    @property
    def live(self) -> np.ndarray:
        """Indices of frames that bootstrap from their next frame (a next frame follows, not terminal)."""
        return np.flatnonzero(self.following & ~self.done)

    @property
    def first(self) -> np.ndarray:
        """bool: the frame opens its episode."""
        return np.r_[True, self.episode[1:] != self.episode[:-1]] if len(self.episode) else np.zeros(0, bool)

    @property
    def episode_success(self) -> dict[int, bool]:
        """``{episode index: succeeded}``."""
        return {int(e): bool(s) for e, s in zip(self.episode[self.first], self.success[self.first])}


def frame_labels(arrays: Mapping[str, np.ndarray], gamma: float | None = None) -> FrameLabels:
    """The :class:`FrameLabels` of ``arrays`` (a view's ``episodes_arrays()``); ``gamma`` adds Monte-Carlo returns."""
    episode = np.asarray(arrays[keys.EPISODE_INDEX])
    n = len(episode)
    flags = np.asarray(arrays[keys.SUCCESS]).astype(bool)
    ids, inverse = np.unique(episode, return_inverse=True)
    succeeded = np.zeros(len(ids), dtype=bool)
    np.logical_or.at(succeeded, inverse, flags)
    following = np.zeros(n, dtype=bool)
    following[:-1] = episode[1:] == episode[:-1]
    done = np.asarray(arrays[keys.DONE]).astype(bool)
    reward = np.asarray(arrays[keys.REWARD]).astype(np.float64)
    ret = None
    if gamma is not None:
        ret = np.zeros(n)
        for i in range(n - 1, -1, -1):
            ret[i] = reward[i] + (gamma * ret[i + 1] if following[i] and not done[i] else 0.0)
    return FrameLabels(episode, succeeded[inverse], following, done, reward, ret)
