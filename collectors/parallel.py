"""Parallel collection: worker processes, one simulator (and GL context) each.

Episodes come back in index order whatever the number of workers, and each is
a pure function of ``(seed, index)`` (see :mod:`.rollout`), so a collection
gives identical episodes for any worker count.  A ``runner`` (a :data:`ChunkRunner`,
e.g. ``nsl.cluster``'s Ray runner) runs the chunks elsewhere instead of local processes.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import sys
from collections.abc import Callable, Iterable, Iterator

from .env import EnvConfig
from .rollout import Episode, PolicyFactory, make_envs, run_episodes

_WORKER: dict = {}

ChunkRunner = Callable[[EnvConfig, PolicyFactory, list[list[int]], int, int], Iterable[list[Episode]]]
"""``runner(config, make_policy, chunks, seed, batch)`` -> each chunk's episodes, chunk by chunk in order."""


def _init_worker(config: EnvConfig, make_policy: PolicyFactory, batch: int, seed: int) -> None:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    policy = make_policy()
    torch = sys.modules.get("torch")  # a learned policy brings torch; keep it to one thread per worker
    if torch is not None:
        torch.set_num_threads(1)
    _WORKER.update(envs=make_envs(config, batch), policy=policy, seed=seed)


def _run_chunk(indices: list[int]) -> list[Episode]:
    return list(run_episodes(_WORKER["envs"], _WORKER["policy"], indices, _WORKER["seed"]))


def collect_episodes(
    config: EnvConfig,
    make_policy: PolicyFactory,
    indices: Iterable[int],
    seed: int,
    workers: int = 1,
    batch: int = 1,
    runner: ChunkRunner | None = None,
) -> Iterator[Episode]:
    """Yield episodes ``indices`` in order, run by ``workers`` processes.

    ``make_policy`` is called once in each worker (it must be picklable, e.g. a
    ``functools.partial``); ``batch`` environments per worker step in lock-step
    and the policy is called once per step for all of them.  With a ``runner``,
    ``workers`` is ignored and the runner runs the chunks of ``batch`` episodes.
    """
    indices = list(indices)
    if workers < 1:
        from nsl.errors import ConfigError

        raise ConfigError(f"workers {workers} must be at least 1")
    chunks = [indices[k : k + batch] for k in range(0, len(indices), batch)]
    if runner is not None:
        for episodes in runner(config, make_policy, chunks, seed, batch):
            yield from episodes
        return
    if workers == 1:
        # In the caller's process: no thread limits (a trainer evaluating in-process keeps its threads).
        _WORKER.update(envs=make_envs(config, batch), policy=make_policy(), seed=seed)
        try:
            for chunk in chunks:
                yield from _run_chunk(chunk)
        finally:
            for env in _WORKER.pop("envs", []):
                env.close()
            _WORKER.clear()
        return
    ctx = mp.get_context("forkserver")
    # Workers fork from a server that already imported MuJoCo and parsed the meshes, and torch
    # when the caller uses it (a checkpoint's policy), so they start in milliseconds.
    ctx.set_forkserver_preload(["nsl.collectors.preload"] + (["torch"] if "torch" in sys.modules else []))
    with ctx.Pool(workers, initializer=_init_worker, initargs=(config, make_policy, batch, seed)) as pool:
        for episodes in pool.imap(_run_chunk, chunks):
            yield from episodes
