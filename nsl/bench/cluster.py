"""``nsl bench cluster``: collection throughput on Ray with N CPUs vs N local worker processes.

Both collect the same episodes (scripted oracle, 64x64, seed 0, chunks of
``--batch``) in one invocation, in a temporary workspace:

* ``local_episodes_per_s``: ``collect_episodes`` with ``--cpus`` forkserver
  worker processes, wall time including the pool's start;
* ``ray_episodes_per_s``: the same call with the Ray chunk runner on a Ray
  instance started here with ``--cpus`` CPUs (``ray.init``, timed separately
  as ``ray_init_s``, is paid once per command or cluster, not per collection),
  wall time including the Ray workers' first chunk (imports, renderer);
* ``ray_vs_local``: their ratio (target at least 0.9); the ``_after_startup``
  variants time both from the first episode's arrival;
* ``same_episodes``: whether the two runs returned identical episodes;
* ``bytes_per_episode``: the serialised size of an episode, what each one
  costs the object store and the network on its way to the driver.

Other processes on the machine take CPU from both sides: read the figures
with ``load_average_1min``.
"""

from __future__ import annotations

import os
import time

HELP = "collection episodes/s: Ray with 2 CPUs vs 2 local worker processes, same episodes (target ratio >= 0.9)"


def add_arguments(p) -> None:
    p.add_argument("--episodes", type=int, default=None, help="episodes per measurement (default 600, quick 150)")
    p.add_argument("--cpus", type=int, default=2, help="local workers and Ray CPUs (default 2)")
    p.add_argument("--batch", type=int, default=1, help="episodes per chunk, as nsl collect --batch (default 1)")


def _collect(n: int, cpus: int, batch: int, runner=None) -> tuple[list, float, float]:
    """The episodes, the wall time, and the time after the first episode arrived."""
    import functools

    from nsl.collectors import EnvConfig, collect_episodes, scripted_policy

    make_policy = functools.partial(scripted_policy, "oracle:0.3")
    episodes, first = [], 0.0
    t0 = time.perf_counter()
    for ep in collect_episodes(EnvConfig(image_size=64), make_policy, range(n), seed=0, workers=cpus, batch=batch,
                               runner=runner):
        episodes.append(ep)
        first = first or time.perf_counter()
    end = time.perf_counter()
    return episodes, end - t0, end - first


def _same(a: list, b: list) -> bool:
    import numpy as np

    return len(a) == len(b) and all(
        x.index == y.index and x.success == y.success and np.array_equal(x.images, y.images)
        and np.array_equal(x.actions, y.actions) and np.array_equal(x.rewards, y.rewards) for x, y in zip(a, b))


def run(args) -> dict:
    import sys

    from nsl.cluster import RayExecutor

    n = args.episodes or (150 if args.quick else 600)
    os.environ.setdefault("RAY_AUTH_MODE", "disabled")  # a throw-away local instance needs no token
    local, t_local, steady_local = _collect(n, args.cpus, args.batch)

    t0 = time.perf_counter()
    executor = RayExecutor("ray", {"num_cpus": args.cpus, "object_store_memory": 200 * 1024 * 1024})
    try:
        executor.connect()
        t_init = time.perf_counter() - t0
        on_ray, t_ray, steady_ray = _collect(n, args.cpus, args.batch, runner=executor.runner)
        from ray import cloudpickle

        sizes = [len(cloudpickle.dumps(ep, protocol=5)) for ep in on_ray[:50]]
        info = executor.describe()
    finally:
        executor.close()
    frames = sum(e.length for e in local)
    print(f"collected {n} episodes ({frames} frames) twice: {t_local:.1f} s on {args.cpus} local workers, "
          f"{t_ray:.1f} s on Ray with {args.cpus} CPUs (+{t_init:.1f} s ray.init)", file=sys.stderr)
    return {
        "local_episodes_per_s": round(n / t_local, 2),
        "ray_episodes_per_s": round(n / t_ray, 2),
        "ray_vs_local": round(t_local / t_ray, 3),
        "local_episodes_per_s_after_startup": round((n - 1) / steady_local, 2),
        "ray_episodes_per_s_after_startup": round((n - 1) / steady_ray, 2),
        "ray_vs_local_after_startup": round(steady_local / steady_ray, 3),
        "episodes_per_s_per_cpu_ray": round(n / t_ray / args.cpus, 2),
        "ray_init_s": round(t_init, 2),
        "same_episodes": _same(local, on_ray),
        "bytes_per_episode": int(sum(sizes) / len(sizes)),
        "frames_per_episode": round(frames / n, 2),
        "episodes": n, "batch": args.batch, "cpus": args.cpus, "ray": info["ray"],
        "cpu_count": os.cpu_count(), "load_average_1min": round(os.getloadavg()[0], 2),
    }
