"""Collection and evaluation chunks as Ray tasks, returned in index order.

``collect_episodes(config, make_policy, indices, seed, batch=B, runner=RayChunkRunner(...))``
cuts ``indices`` into chunks of ``B`` episodes, exactly as with local
processes.  Each chunk becomes a Ray task holding one CPU:

* **Warm workers.**  A Ray worker process keeps the environments (renderer and
  GL context) and the policy of the collection it last served, so only the
  first chunk a process runs pays for building them; a checkpoint's policy is
  loaded once per process, not once per chunk.
* **Same episodes.**  Episode ``i`` is a pure function of ``(seed, i)``
  whichever node runs it; the driver receives the chunks in order and writes
  the dataset as a local run would, so versions, resume and hashes are
  unchanged.  A worker whose simulator (``ENV_VERSION``) differs from the
  driver's refuses to run.
* **Few tasks.**  A task runs ``chunks_per_task`` consecutive chunks (default:
  enough for 8 episodes, fewer when that would leave under 4 tasks per CPU),
  so Ray's per-task cost (about a millisecond of driver and raylet time) stays
  small next to the simulation.
* **Bounded memory.**  At most ``window`` tasks are in flight (default two per
  cluster CPU); a task's episodes leave the object store once the driver has
  them.
* **Lost nodes.**  A chunk whose worker or node dies is run again elsewhere by
  Ray (``max_retries``); a finished chunk lost with its node is rebuilt from
  its lineage.  Because chunks are pure, a rerun gives the same episodes.
"""

from __future__ import annotations

import os
import sys
import uuid
from collections import Counter, deque
from collections.abc import Iterator
from typing import Any

from .tasks import _remote, get

_WORKER: dict[str, Any] = {}  # in each Ray worker process: the setup of the collection it last served


class RayChunkRunner:
    """A ``ChunkRunner`` for ``collect_episodes`` that runs chunks on the executor's Ray cluster."""

    def __init__(self, executor, window: int | None = None, chunks_per_task: int | None = None):
        self.executor = executor
        self.window = window  # tasks in flight; None: two per cluster CPU (at least 4)
        self.chunks_per_task = chunks_per_task  # None: enough chunks for 8 episodes (fewer in short runs)
        self.chunks_per_node: Counter[str] = Counter()  # node id -> chunks it returned (for tests and the bench)

    def __call__(self, config, make_policy, chunks: list[list[int]], seed: int, batch: int) -> Iterator[list]:
        from nsl.collectors import ENV_VERSION

        ray = self.executor.connect()
        cpus = self.executor.cpus()
        window = self.window or max(4, 2 * cpus)
        setup = ray.put(
            {
                "key": uuid.uuid4().hex,
                "config": config,
                "make_policy": make_policy,
                "batch": batch,
                "env_version": ENV_VERSION,
            }
        )
        task = _remote(ray, _run_chunks).options(
            num_cpus=1, max_retries=self.executor.max_retries, retry_exceptions=False
        )
        # about 8 episodes a task, but at least 4 tasks per CPU so that short runs spread and end together
        per_task = self.chunks_per_task or max(1, min(-(-8 // batch), -(-len(chunks) // (4 * cpus))))
        todo = deque(chunks[k : k + per_task] for k in range(0, len(chunks), per_task))
        flight: deque = deque()
        try:
            while todo or flight:
                while todo and len(flight) < window:
                    flight.append(task.remote(setup, todo.popleft(), seed))
                node, results = get(ray, flight.popleft())
                self.chunks_per_node[node] += len(results)
                yield from results
        finally:
            for ref in flight:  # the caller stopped early (interrupt, error): drop the chunks still running
                ray.cancel(ref)


def _run_chunks(setup: dict, chunks: list[list[int]], seed: int) -> tuple[str, list[list]]:
    """In a Ray worker: each chunk's episodes (and the node that ran them)."""
    import ray

    from nsl.collectors import ENV_VERSION, run_episodes

    if setup["env_version"] != ENV_VERSION:
        from nsl.errors import IncompatibleVersionError

        raise IncompatibleVersionError(
            f"node {ray.get_runtime_context().get_node_id()[:12]} runs simulator version {ENV_VERSION} but the driver "
            f"runs {setup['env_version']}; install the same nsl on every node"
        )
    if _WORKER.get("key") != setup["key"]:
        _warm(setup)
    results = [list(run_episodes(_WORKER["envs"], _WORKER["policy"], indices, seed)) for indices in chunks]
    return ray.get_runtime_context().get_node_id(), results


def _warm(setup: dict) -> None:
    """Build the environments and the policy of a new collection in this worker (closing the last one's)."""
    from nsl.collectors import make_envs

    for env in _WORKER.pop("envs", []):
        env.close()
    _WORKER.clear()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    policy = setup["make_policy"]()
    torch = sys.modules.get("torch")  # a learned policy brings torch; one thread per CPU-holding task
    if torch is not None:
        torch.set_num_threads(1)
    _WORKER.update(key=setup["key"], envs=make_envs(setup["config"], setup["batch"]), policy=policy)
