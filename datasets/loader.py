"""The training loader: transitions from one or more dataset views, mixed by weight.

Images are decoded once per version into a uint8 ``.npy`` file under
``$NSL_HOME/cache/datasets/<version hash>/`` and memory-mapped; the cache is
rebuilt when it is missing, truncated or was built for other content.  The
numeric columns are read from Parquet into memory.  Sampling a batch is numpy
fancy indexing on precomputed transition indices: no Python work per frame.

Transitions: frame ``t`` of an episode with its successor ``t + 1``.  The last
frame of a terminated episode is a terminal transition (done = 1; its next
observation is the frame itself and must be ignored); the last frame of a
truncated episode has no successor and is left out.

With ``n_step > 1`` a transition spans up to n frames of its episode
(Sutton & Barto's n-step return, taken along the data's own actions)::

    reward   = r_t + gamma r_{t+1} + ... + gamma^(k-1) r_{t+k-1}
    next     = frame t + k             (k <= n; fewer where the episode ends)
    discount = gamma^k                 (the learner's bootstrap factor)
    done     = the episode terminated within those k frames

and batches carry ``keys.DISCOUNT``.  A truncated episode's chain stops at its
last frame that has a successor.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from nsl import keys
from nsl.errors import ConfigError, CorruptDataError
from nsl.workspace import atomic_write_json, cache_dir

from . import layout
from .reader import DatasetVersion, DatasetView, open_view

CACHE_FILE = "observation.image.npy"
CACHE_META = "cache.json"


def _cache_path(version: DatasetVersion) -> Path:
    return cache_dir() / layout.CACHE_DIR.format(version_hash=version.hash.split(":")[-1])


def _open_cache(path: Path, version: DatasetVersion) -> np.ndarray | None:
    s = version.image_size
    try:
        meta = json.loads((path / CACHE_META).read_text())
        arr = np.load(path / CACHE_FILE, mmap_mode="r")
    except (OSError, ValueError, json.JSONDecodeError):
        return None
    if meta.get("hash") != version.hash or arr.shape != (version.num_frames, s, s, 3) or arr.dtype != np.uint8:
        return None
    return arr


def image_cache(version: DatasetVersion, progress: bool = False) -> np.ndarray:
    """The version's images as a read-only (N, H, W, 3) uint8 memory map, decoding them if needed."""
    path = _cache_path(version)
    arr = _open_cache(path, version)
    if arr is not None:
        return arr
    path.mkdir(parents=True, exist_ok=True)
    s = version.image_size
    tmp = path / f".{CACHE_FILE}.{os.getpid()}.tmp"
    out = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.uint8, shape=(version.num_frames, s, s, 3))
    try:
        view = version.view()
        if progress:
            print(f"decoding {version.num_frames} images of {version.ref} into {path}")
        view.decode_images(out)
        out.flush()
        del out
        os.replace(tmp, path / CACHE_FILE)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    atomic_write_json(
        path / CACHE_META,
        {
            "hash": version.hash,
            "ref": version.ref,
            "frames": version.num_frames,
            "shape": [version.num_frames, s, s, 3],
        },
    )
    arr = _open_cache(path, version)
    assert arr is not None
    return arr


def n_step_returns(
    reward: np.ndarray, done: np.ndarray, has_next: np.ndarray, start: np.ndarray, n: int, gamma: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For transitions starting at frames ``start``: (return, next frame, gamma^k, terminated), all (len(start),).

    ``reward``, ``done`` and ``has_next`` are per frame of episodes stored back to back; ``has_next``
    marks the frames that start a transition (all but a truncated episode's last frame).  Vectorised over
    transitions, one pass per step of the chain.
    """
    ret = np.zeros(len(start))
    disc = np.ones(len(start))
    cur, nxt = start.copy(), start.copy()
    term = np.zeros(len(start), bool)
    active = np.ones(len(start), bool)
    for k in range(n):
        ret[active] += disc[active] * reward[cur[active]]
        disc[active] *= gamma
        ends = active & done[cur]
        term |= ends
        nxt[ends] = cur[ends]  # a terminal transition's next observation is never used
        active &= ~ends
        succ = np.where(active, cur + 1, cur)  # an active frame is no episode's last: its successor is t + 1
        go_on = active & has_next[succ] if k + 1 < n else np.zeros_like(active)
        stop = active & ~go_on
        nxt[stop] = succ[stop]
        cur = np.where(go_on, succ, cur)
        active = go_on
    return ret, nxt, disc, term


class TransitionSource:
    """The transitions of one view: index arrays into the image cache plus in-memory numeric columns."""

    def __init__(self, view: DatasetView, verify: bool = True, n_step: int = 1, gamma: float = 1.0):
        self.view = view
        self.n_step, self.gamma = n_step, gamma
        if verify:
            view.check()
        cols = view.read_columns((keys.OBS_STATE, keys.ACTION, keys.REWARD, keys.DONE, keys.INDEX, keys.EPISODE_INDEX))
        self.images = image_cache(view.version)
        n = len(cols[keys.INDEX])
        first = view.frame_range[0]
        if not np.array_equal(cols[keys.INDEX], np.arange(first, first + n)):
            raise CorruptDataError(
                f"{view.version.ref}: the frame index column of {view.data_files()[0]} "
                "is not contiguous; run `nsl dataset verify`"
            )
        ep = cols[keys.EPISODE_INDEX]
        last = np.r_[ep[1:] != ep[:-1], True]
        done = cols[keys.DONE].astype(bool)
        keep = ~last | done  # a truncated (or unfinished) episode's last frame has no successor
        local = np.flatnonzero(keep)
        self.obs_index = first + local  # into the image cache (global frame index)
        self._first = first
        self.states = cols[keys.OBS_STATE].astype(np.float32)  # per frame of the view (index - first)
        self.actions = cols[keys.ACTION].astype(np.float32)[local]  # per transition
        reward, nxt, discount, term = n_step_returns(
            cols[keys.REWARD].astype(np.float64), done, keep, local, n_step, gamma
        )
        self.next_index = first + nxt
        self.reward, self.discount, self.done = (
            reward.astype(np.float32),
            discount.astype(np.float32),
            term.astype(np.float32),
        )

    def __len__(self) -> int:
        return len(self.obs_index)

    def fill(self, out: dict[str, np.ndarray], sl: slice, rng: np.random.Generator) -> None:
        """Write ``sl.stop - sl.start`` random transitions into ``out[...][sl]``."""
        j = rng.integers(0, len(self.obs_index), sl.stop - sl.start)
        oi, ni = self.obs_index[j], self.next_index[j]
        np.take(self.images, oi, axis=0, out=out[keys.OBS_IMAGE][sl])
        np.take(self.images, ni, axis=0, out=out[keys.NEXT_OBS_IMAGE][sl])
        np.take(self.states, oi - self._first, axis=0, out=out[keys.OBS_STATE][sl])
        np.take(self.states, ni - self._first, axis=0, out=out[keys.NEXT_OBS_STATE][sl])
        np.take(self.reward, j, out=out[keys.REWARD][sl])
        np.take(self.done, j, out=out[keys.DONE][sl])
        np.take(self.actions, j, axis=0, out=out[keys.ACTION][sl])
        if keys.DISCOUNT in out:
            np.take(self.discount, j, out=out[keys.DISCOUNT][sl])

    def describe(self) -> dict[str, Any]:
        return {**self.view.describe(), "transitions": len(self)}


class Sampler:
    """Random transition batches from weighted sources (the learner's data contract).

    ``sample(batch_size, rng)`` returns ``nsl.keys`` arrays: ``OBS_IMAGE`` and
    ``NEXT_OBS_IMAGE`` (B, H, W, 3) uint8, ``OBS_STATE`` and ``NEXT_OBS_STATE``
    (B, 2) float32, ``ACTION`` (B, 6) float32, ``REWARD`` and ``DONE`` (B,)
    float32.  Each element's source is drawn by weight; the batch holds the
    sources in contiguous blocks.
    """

    def __init__(self, sources: Sequence[TransitionSource], weights: Sequence[float]):
        sizes = {s.view.version.image_size for s in sources}
        if len(sizes) != 1:
            raise ConfigError(
                f"cannot mix datasets of different image sizes {sorted(sizes)}; collect them with the same --image-size"
            )
        self.sources = list(sources)
        w = np.asarray(weights, dtype=np.float64)
        self.weights = w / w.sum()
        self.image_size = sizes.pop()
        steps = {(s.n_step, s.gamma) for s in self.sources}
        if len(steps) != 1:
            raise ConfigError(f"sources disagree on (n_step, gamma): {sorted(steps)}; build them with the same values")
        self.n_step, self.gamma = steps.pop()

    def __len__(self) -> int:
        return sum(len(s) for s in self.sources)

    def sample(self, batch_size: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        b, s = int(batch_size), self.image_size
        out: dict[str, np.ndarray] = {
            keys.OBS_IMAGE: np.empty((b, s, s, 3), np.uint8),
            keys.NEXT_OBS_IMAGE: np.empty((b, s, s, 3), np.uint8),
            keys.OBS_STATE: np.empty((b, keys.STATE_DIM), np.float32),
            keys.NEXT_OBS_STATE: np.empty((b, keys.STATE_DIM), np.float32),
            keys.ACTION: np.empty((b, keys.ACTION_DIM), np.float32),
            keys.REWARD: np.empty(b, np.float32),
            keys.DONE: np.empty(b, np.float32),
        }
        if self.n_step > 1:
            out[keys.DISCOUNT] = np.empty(b, np.float32)
        counts = rng.multinomial(b, self.weights) if len(self.sources) > 1 else [b]
        at = 0
        for src, k in zip(self.sources, counts):
            if k:
                src.fill(out, slice(at, at + int(k)), rng)
                at += int(k)
        return out

    def tables(self) -> list[tuple[dict[str, np.ndarray], float]]:
        """Each source's transitions as arrays, with its weight: ``images`` (its image cache), the frame indices
        ``obs`` and ``next`` into it, and the per-transition columns (what a GPU copies to sample there)."""
        out = []
        for src, w in zip(self.sources, self.weights):
            table = {
                "images": src.images,
                "obs": src.obs_index,
                "next": src.next_index,
                keys.OBS_STATE: src.states[src.obs_index - src._first],
                keys.NEXT_OBS_STATE: src.states[src.next_index - src._first],
                keys.ACTION: src.actions,
                keys.REWARD: src.reward,
                keys.DONE: src.done,
            }
            if self.n_step > 1:
                table[keys.DISCOUNT] = src.discount
            out.append((table, float(w)))
        return out

    def describe(self) -> dict[str, Any]:
        return {
            "transitions": len(self),
            "image_size": self.image_size,
            **({"n_step": self.n_step, "gamma": self.gamma} if self.n_step > 1 else {}),
            "sources": [{**s.describe(), "weight": float(w)} for s, w in zip(self.sources, self.weights)],
        }


SourceSpec = str | DatasetView


def make_sampler(
    sources: SourceSpec | Sequence[tuple[SourceSpec, float]],
    verify: bool = True,
    n_step: int = 1,
    gamma: float | None = None,
) -> Sampler:
    """A sampler over ``[(ref or view, weight), ...]`` (or a single ref/view with weight 1).

    ``verify`` re-hashes the data files each source reads and refuses damaged
    ones (CorruptDataError names the file).  ``n_step > 1`` gives n-step
    transitions discounted by ``gamma`` (see the module docstring).
    """
    if not (isinstance(n_step, int) and n_step >= 1):
        raise ConfigError(f"n_step {n_step!r} must be a whole number >= 1")
    if n_step > 1 and (gamma is None or not 0 <= gamma <= 1):
        raise ConfigError(f"n-step transitions need the discount gamma in [0, 1]; got {gamma!r}")
    pairs = [(sources, 1.0)] if isinstance(sources, (str, DatasetView)) else list(sources)
    if not pairs:
        raise ConfigError(
            "make_sampler needs at least one (dataset, weight) pair, e.g. [('grasp-base', 0.5), "
            "('grasp-harsh:100', 0.5)]"
        )
    for ref, w in pairs:
        if not (isinstance(w, (int, float)) and w > 0 and np.isfinite(w)):
            raise ConfigError(f"weight {w!r} of {ref} must be a positive number")
    built = [
        TransitionSource(open_view(ref), verify=verify, n_step=n_step, gamma=1.0 if gamma is None else gamma)
        for ref, _ in pairs
    ]
    for (ref, _), src in zip(pairs, built):
        if len(src) == 0:
            raise ConfigError(f"dataset {ref} has no transitions (every episode was a one-frame truncation)")
    return Sampler(built, [w for _, w in pairs])
