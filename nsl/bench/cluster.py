"""``nsl bench cluster``: collection throughput on Ray with N CPUs vs N local worker processes.

Both collect the same episodes (64x64, seed 0, chunks of ``--batch-size``) in one
invocation, with the scripted oracle or, with ``--policy base``, the shipped
base checkpoint's CEM policy (what a study's collections and evaluations run):

* ``local_episodes_per_s``: ``collect_episodes`` with ``--cpus`` forkserver
  worker processes, wall time including the pool's start;
* ``ray_episodes_per_s``: the same call with the Ray chunk runner on a Ray
  instance started here with ``--cpus`` CPUs (``ray.init``, timed separately
  as ``ray_init_s``, is paid once per command or cluster, not per collection),
  wall time including the Ray workers' first chunk (imports, renderer);
* ``ray_vs_local``: their ratio (target at least 0.9), from the best of
  ``--rounds`` alternated runs of each (the first Ray round also starts its
  workers: ``ray_vs_local_first_round``); the ``_after_startup`` variants time
  both from the first episode's arrival;
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
    p.add_argument("--batch-size", type=int, default=1, help="environments per chunk, as nsl collect --batch-size")
    p.add_argument(
        "--rounds",
        type=int,
        default=None,
        help="local and Ray runs, alternated; the best of each counts (default 3, quick 1)",
    )
    p.add_argument(
        "--policy",
        default="oracle:0.3",
        help="oracle[:NOISE] (default oracle:0.3) or base (the shipped checkpoint's CEM policy)",
    )


def _policy(ref: str):
    """A picklable policy factory (built once here: it validates, and imports torch before workers fork)."""
    import functools
    from pathlib import Path

    import nsl
    from nsl.collectors import scripted_policy

    if ref == "base":
        from nsl.learners import load_policy

        make_policy = functools.partial(load_policy, str(Path(nsl.__file__).parent / "assets" / "base"))
    else:
        make_policy = functools.partial(scripted_policy, ref)
    make_policy()
    return make_policy


def _collect(make_policy, n: int, cpus: int, batch: int, runner=None) -> tuple[list, float, float]:
    """The episodes, the wall time, and the time after the first episode arrived."""
    from nsl.collectors import EnvConfig, collect_episodes

    episodes, first = [], 0.0
    t0 = time.perf_counter()
    for ep in collect_episodes(
        EnvConfig(image_size=64), make_policy, range(n), seed=0, workers=cpus, batch=batch, runner=runner
    ):
        episodes.append(ep)
        first = first or time.perf_counter()
    end = time.perf_counter()
    return episodes, end - t0, end - first


def _same(a: list, b: list) -> bool:
    import numpy as np

    return len(a) == len(b) and all(
        x.index == y.index
        and x.success == y.success
        and np.array_equal(x.images, y.images)
        and np.array_equal(x.actions, y.actions)
        and np.array_equal(x.rewards, y.rewards)
        for x, y in zip(a, b)
    )


def run(args) -> dict:
    import sys

    from nsl.cluster import RayExecutor

    n = args.episodes or (150 if args.quick else 600)
    rounds = args.rounds or (1 if args.quick else 3)
    os.environ.setdefault("RAY_AUTH_MODE", "disabled")  # a throw-away local instance needs no token
    make_policy = _policy(args.policy)
    t0 = time.perf_counter()
    executor = RayExecutor("ray", {"num_cpus": args.cpus, "object_store_memory": 200 * 1024 * 1024})
    local_runs, ray_runs = [], []
    try:
        executor.connect()
        t_init = time.perf_counter() - t0
        for _ in range(rounds):  # alternate, so that load from other processes falls on both sides
            local, *times = _collect(make_policy, n, args.cpus, args.batch_size)
            local_runs.append(times)
            on_ray, *times = _collect(make_policy, n, args.cpus, args.batch_size, runner=executor.runner)
            ray_runs.append(times)
            if not _same(local, on_ray):
                break
        from ray import cloudpickle

        sizes = [len(cloudpickle.dumps(ep, protocol=5)) for ep in on_ray[:50]]
        info = executor.describe()
    finally:
        executor.close()
    (t_local, steady_local), (t_ray, steady_ray) = min(local_runs), min(ray_runs)  # best round of each
    frames = sum(e.length for e in local)
    print(
        f"collected {n} episodes ({frames} frames) {rounds} times each: best {t_local:.1f} s on {args.cpus} local "
        f"workers (all: {', '.join(f'{t:.1f}' for t, _ in local_runs)}), best {t_ray:.1f} s on Ray with "
        f"{args.cpus} CPUs (all: {', '.join(f'{t:.1f}' for t, _ in ray_runs)}; ray.init {t_init:.1f} s)",
        file=sys.stderr,
    )
    return {
        "local_episodes_per_s": round(n / t_local, 2),
        "ray_episodes_per_s": round(n / t_ray, 2),
        "ray_vs_local": round(t_local / t_ray, 3),
        "local_episodes_per_s_after_startup": round((n - 1) / steady_local, 2),
        "ray_episodes_per_s_after_startup": round((n - 1) / steady_ray, 2),
        "ray_vs_local_after_startup": round(steady_local / steady_ray, 3),
        "ray_vs_local_first_round": round(local_runs[0][0] / ray_runs[0][0], 3),  # Ray's workers start cold
        "episodes_per_s_per_cpu_ray": round(n / t_ray / args.cpus, 2),
        "ray_init_s": round(t_init, 2),
        "same_episodes": _same(local, on_ray),
        "bytes_per_episode": int(sum(sizes) / len(sizes)),
        "frames_per_episode": round(frames / n, 2),
        "episodes": n,
        "rounds": len(local_runs),
        "batch": args.batch_size,
        "policy": args.policy,
        "cpus": args.cpus,
        "ray": info["ray"],
        "cpu_count": os.cpu_count(),
        "load_average_1min": round(os.getloadavg()[0], 2),
    }
