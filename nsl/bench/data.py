"""``nsl bench data``: dataset write and random-read speed, nsl vs LeRobot, and parallel collection.

All figures come from one invocation on the same 64x64 episodes (collected
here with the scripted oracle), in a temporary workspace:

* ``collect_speedup_2_workers``: wall time of ``collect_episodes`` with 1
  worker over 2 workers (process start-up included), same episodes; the
  ``_after_startup`` variant times both from the first episode's arrival.
  Another busy process on the machine takes a core from the 2 workers, so
  read it with ``load_average_1min``;
* ``writer_frames_per_s``: ``nsl.datasets`` writing a version (PNG encoding,
  Parquet, stats, hashes, publication) vs ``lerobot_writer_frames_per_s``:
  ``LeRobotDataset.create`` + ``add_frame`` + ``save_episode`` + ``finalize``;
* ``loader_frames_per_s``: transitions per second from ``Sampler.sample(256)``
  (each with its next observation) vs ``lerobot_loader_frames_per_s``: random
  ``LeRobotDataset.__getitem__`` on LeRobot's own copy of the data.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

HELP = "dataset writer/loader frames/s vs LeRobot and 2-worker collection speed-up (targets 10x, 30x, 1.7)"


def add_arguments(p) -> None:
    p.add_argument(
        "--episodes",
        type=int,
        default=None,
        help="episodes collected for the speed-up and the data (default 480, quick 200)",
    )
    p.add_argument(
        "--lerobot-episodes",
        type=int,
        default=None,
        help="episodes written with LeRobot's writer (default 200, quick 60)",
    )
    p.add_argument("--seconds", type=float, default=None, help="time per loader measurement (default 3, quick 1.5)")


def _collect(n: int, workers: int) -> tuple[list, float, float]:
    """The episodes, the wall time, and the time after the first episode arrived (start-up excluded)."""
    import functools

    from nsl.collectors import EnvConfig, collect_episodes, scripted_policy

    make_policy = functools.partial(scripted_policy, "oracle:0.3")
    episodes, first = [], 0.0
    t0 = time.perf_counter()
    for ep in collect_episodes(EnvConfig(image_size=64), make_policy, range(n), seed=0, workers=workers):
        episodes.append(ep)
        first = first or time.perf_counter()
    end = time.perf_counter()
    return episodes, end - t0, end - first


def _lerobot_write(episodes: list, root: Path):
    import numpy as np
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from nsl import keys
    from nsl.datasets.api import layout

    features = {
        k: {**ft, "shape": tuple(ft["shape"])}
        for k, ft in layout.features(64).items()
        if k not in layout.INDEX_KEYS and k != keys.TIMESTAMP
    }
    t0 = time.perf_counter()
    ds = LeRobotDataset.create("bench/lerobot", fps=keys.FPS, features=features, root=root, use_videos=False)
    for ep in episodes:
        t = len(ep.actions)
        for i in range(t):
            last = i == t - 1
            ds.add_frame(
                {
                    keys.OBS_IMAGE: ep.images[i],
                    keys.OBS_STATE: ep.states[i],
                    keys.ACTION: ep.actions[i],
                    keys.REWARD: np.array([ep.rewards[i]], np.float32),
                    keys.DONE: np.array([last and ep.terminated]),
                    keys.SUCCESS: np.array([last and ep.success]),
                    keys.TRUNCATED: np.array([last and ep.truncated and not ep.terminated]),
                    "task": layout.DEFAULT_TASK,
                }
            )
        ds.save_episode()
    ds.finalize()
    return time.perf_counter() - t0


def _time_calls(fn, seconds: float, min_calls: int = 3) -> tuple[int, float]:
    calls, t0 = 0, time.perf_counter()
    while calls < min_calls or time.perf_counter() - t0 < seconds:
        fn(calls)
        calls += 1
    return calls, time.perf_counter() - t0


def run(args) -> dict:
    import contextlib
    import io
    import logging
    import sys

    import numpy as np

    n = args.episodes or (200 if args.quick else 480)
    n_lerobot = min(n, args.lerobot_episodes or (60 if args.quick else 200))
    seconds = args.seconds or (1.5 if args.quick else 3.0)
    home = Path(tempfile.mkdtemp(prefix="nsl-bench-data-"))
    saved = {k: os.environ.get(k) for k in ("NSL_HOME", "HF_HUB_OFFLINE")}
    os.environ["NSL_HOME"] = str(home / "nsl")
    os.environ["HF_HUB_OFFLINE"] = "1"
    try:
        import datasets.config

        datasets.config.HF_DATASETS_CACHE = home / "hf_cache"
        logging.getLogger("datasets").setLevel(logging.ERROR)

        _, t1, steady1 = _collect(n, workers=1)
        episodes, t2, steady2 = _collect(n, workers=2)

        from nsl.collectors import scripted_policy
        from nsl.datasets import api

        spec = {
            "env": {"shift": "base", "image_size": 64},
            "policy": scripted_policy("oracle:0.3").describe(),
            "policy_ref": "oracle:0.3",
            "seed": 0,
        }
        frames = sum(len(e.actions) for e in episodes)
        api.write_dataset("warm-up", episodes[:2], spec, 64, 2)  # imports (cv2, pandas), thread pool: untimed
        t0 = time.perf_counter()
        version = api.write_dataset("bench", episodes, spec, 64, len(episodes))
        t_write = time.perf_counter() - t0

        sub = episodes[:n_lerobot]
        sub_frames = sum(len(e.actions) for e in sub)
        with contextlib.redirect_stderr(io.StringIO()):  # LeRobot's per-episode progress bars
            t_lerobot_write = _lerobot_write(sub, home / "lerobot")

        t0 = time.perf_counter()
        sampler = api.make_sampler("bench")
        t_open = time.perf_counter() - t0
        rng = np.random.default_rng(0)
        calls, dt = _time_calls(lambda _: sampler.sample(256, rng), seconds)
        loader = calls * 256 / dt

        from lerobot.datasets.lerobot_dataset import LeRobotDataset

        with contextlib.redirect_stderr(io.StringIO()):
            ds = LeRobotDataset("bench/lerobot", root=home / "lerobot")
        idx = np.random.default_rng(0).integers(0, len(ds), 1_000_000)
        ds[int(idx[0])]  # warm-up
        calls_lr, dt_lr = _time_calls(lambda i: ds[int(idx[i])], seconds, min_calls=50)
        lerobot_loader = calls_lr / dt_lr
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        import shutil

        shutil.rmtree(home, ignore_errors=True)
    writer = frames / t_write
    lerobot_writer = sub_frames / t_lerobot_write
    print(
        f"collected {n} episodes ({frames} frames) twice: {t1:.1f} s with 1 worker, {t2:.1f} s with 2; "
        f"{version.ref} {version.hash[:19]}",
        file=sys.stderr,
    )
    return {
        "writer_frames_per_s": round(writer, 1),
        "lerobot_writer_frames_per_s": round(lerobot_writer, 1),
        "writer_ratio": round(writer / lerobot_writer, 1),
        "loader_frames_per_s": round(loader, 1),
        "lerobot_loader_frames_per_s": round(lerobot_loader, 1),
        "loader_ratio": round(loader / lerobot_loader, 1),
        "collect_speedup_2_workers": round(t1 / t2, 2),
        "collect_speedup_2_workers_after_startup": round(steady1 / steady2, 2),  # both timed from episode 1
        "collect_episodes_per_s_1_worker": round(n / t1, 2),
        "collect_episodes_per_s_2_workers": round(n / t2, 2),
        "loader_open_s": round(t_open, 2),  # first open: hash check + image cache build
        "episodes": n,
        "frames": frames,
        "lerobot_writer_frames": sub_frames,
        "image_size": 64,
        "cpu_count": os.cpu_count(),
        "load_average_1min": round(os.getloadavg()[0], 2),
    }
