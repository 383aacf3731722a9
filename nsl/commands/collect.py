"""``nsl collect``: run a policy in a (shifted) environment and record a dataset version.

Episode ``i`` is a pure function of ``(seed, i)``, and episodes are written in
fixed runs of ``--episodes-per-file`` through a staging area, so the dataset is
identical for any ``--workers`` and whether or not the run was interrupted:
running the same command again resumes it.  Asking an existing dataset for more
episodes publishes a new version that appends to the latest one.
"""

from __future__ import annotations

import argparse
import functools
import shlex
import sys
import time
from dataclasses import asdict, dataclass
from typing import Any

from nsl.errors import ConfigError


@dataclass(frozen=True)
class CollectConfig:
    """What ``nsl collect`` was asked to do (recorded in the dataset's metadata)."""

    shift: str  # shift spec, e.g. "harsh_lighting" or "harsh_lighting+checkerboard_backing@0.5"
    episodes: int  # total episodes the dataset should hold afterwards
    policy: str  # policy reference: random, oracle[:NOISE] or ckpt:NAME[@...] (a checkpoint's CEM policy)
    dataset: str  # dataset name; an existing name resumes or appends
    workers: int = 1  # simulator processes (does not change the data)
    seed: int = 0  # episode i is a pure function of (seed, i)
    batch: int = 1  # environments per worker stepping in lock-step (a learned policy batches them)
    split: str = "train"  # object split: train or test objects
    image_size: int = 64  # camera resolution in pixels
    episodes_per_file: int = 100  # episodes per Parquet file (also the resume granularity)
    epsilon: float = 0.0  # checkpoint policies: probability of a uniformly random action per step (exploration)

    def __post_init__(self) -> None:
        if self.episodes < 1:
            raise ConfigError(f"--episodes {self.episodes} must be at least 1")
        if self.workers < 1 or self.batch < 1:
            raise ConfigError(f"--workers {self.workers} and --batch {self.batch} must be at least 1")
        if self.episodes_per_file < 1:
            raise ConfigError(f"--episodes-per-file {self.episodes_per_file} must be at least 1")
        if not 0.0 <= self.epsilon <= 1.0:
            raise ConfigError(f"--epsilon {self.epsilon} must be in [0, 1]")
        if self.seed < 0:
            raise ConfigError(f"--seed {self.seed} must be non-negative")


def on_version_created(version) -> None:
    """Record a newly published dataset version (a ``DatasetVersion``) in the catalog."""
    from nsl.catalog import Catalog
    from nsl.resolve import register_dataset

    with Catalog() as cat:
        register_dataset(cat, version)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "collect", help="collect grasp episodes into a versioned dataset (resumable, parallel)",
        description="Run a policy for N episodes in a shifted environment and write them as a LeRobot v3.0 "
                    "dataset version under $NSL_HOME/datasets/NAME/. Running the same command again resumes an "
                    "interrupted collection; asking an existing dataset for more episodes appends a new version.",
        epilog="example: nsl collect --shift harsh_lighting --episodes 800 --policy oracle:0.5 "
               "--dataset grasp-harsh --workers 2")
    p.add_argument("--shift", required=True, help="shift spec: base, harsh_lighting, checkerboard_backing@0.5, ...")
    p.add_argument("--episodes", type=int, required=True, help="total episodes the dataset should hold")
    p.add_argument("--policy", required=True, help="policy: random, oracle[:NOISE] (noise std, e.g. oracle:0.5), "
                                                  "or a checkpoint, ckpt:NAME[@STEP] (its CEM policy; see --epsilon)")
    p.add_argument("--dataset", required=True, help="dataset name (an existing name resumes or appends)")
    p.add_argument("--workers", type=int, default=1, help="simulator processes (default 1; data is identical)")
    p.add_argument("--seed", type=int, default=0, help="collection seed (default 0)")
    p.add_argument("--epsilon", type=float, default=0.0,
                   help="with a ckpt: policy, chance of a random action per step (exploration; default 0)")
    p.add_argument("--batch", type=int, default=1, help="environments per worker in lock-step (default 1)")
    p.add_argument("--split", default="train", choices=["train", "test"], help="object split (default train)")
    p.add_argument("--image-size", type=int, default=64, help="camera resolution in pixels (default 64)")
    p.add_argument("--episodes-per-file", type=int, default=100,
                   help="episodes per Parquet file, also the resume granularity (default 100)")
    p.add_argument("--restart", action="store_true", help="discard an unfinished collection of this dataset")
    p.add_argument("--stop-after-files", type=int, default=0, help=argparse.SUPPRESS)  # tests: simulate a kill
    from nsl.cluster import add_option

    add_option(p)  # --cluster local|ray|auto|ray://HOST:PORT
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from nsl.collectors import EnvConfig, collect_episodes
    from nsl.datasets import api
    from nsl.resolve import policy_factory

    cfg = CollectConfig(shift=args.shift, episodes=args.episodes, policy=args.policy, dataset=args.dataset,
                        workers=args.workers, seed=args.seed, batch=args.batch, split=args.split,
                        image_size=args.image_size, episodes_per_file=args.episodes_per_file,
                        epsilon=args.epsilon)
    env_config = EnvConfig(shift=cfg.shift, split=cfg.split, image_size=cfg.image_size)
    make_policy = policy_factory(cfg.policy, env_config, epsilon=cfg.epsilon)
    spec = {"env": env_config.to_dict(), "policy": make_policy().describe(), "policy_ref": cfg.policy,
            "seed": cfg.seed}
    coll = api.Collection.begin(cfg.dataset, cfg.episodes, spec, cfg.image_size, cfg.episodes_per_file,
                                restart=args.restart)
    if coll.up_to_date:
        v = coll.parent
        print(f"{v.ref} already holds {v.num_episodes} episodes (asked for {cfg.episodes}); nothing to collect"
              + (f"; use {v.name}:{cfg.episodes} for the first {cfg.episodes}" if cfg.episodes < v.num_episodes
                 else ""))
        return 0
    missing = coll.missing_indices()
    if len(missing) < coll.stop - coll.start:
        print(f"resuming {cfg.dataset}: {coll.stop - coll.start - len(missing)} of {coll.stop - coll.start} "
              "episodes already staged", file=sys.stderr)
    started = time.perf_counter()
    from nsl.cluster import open_executor

    with open_executor(args.cluster) as ex:  # local processes, or chunks as Ray tasks (same episodes)
        _collect(coll, cfg, env_config, make_policy, missing, args.stop_after_files,
                 functools.partial(collect_episodes, runner=ex.runner))
    version = coll.finish(created={
        "command": "nsl collect " + shlex.join(_argv(cfg)), "workers": cfg.workers, "batch": cfg.batch,
        "cluster": ex.name,
        "collect_seconds": round(time.perf_counter() - started, 2), "config": asdict(cfg)})
    info = version.describe()
    on_version_created(version)
    print(f"wrote {version.ref}: {version.num_episodes} episodes ({coll.stop - coll.start} new), "
          f"{version.num_frames} frames, success {info['success_rate']:.1%}, {version.hash[:19]}... "
          f"at {version.root}")
    return 0


def _collect(coll, cfg: CollectConfig, env_config, make_policy, missing: list[int], stop_after: int,
             collect_episodes) -> None:
    from tqdm import tqdm

    if not missing:
        return
    episodes = collect_episodes(env_config, make_policy, missing, seed=cfg.seed, workers=cfg.workers,
                                batch=cfg.batch)
    bar = tqdm(total=len(missing), unit="ep", desc=f"collect {cfg.dataset}", dynamic_ncols=True)
    successes = files = 0
    try:
        for k, ep in enumerate(episodes):
            if ep.index != missing[k]:
                raise RuntimeError(f"collector returned episode {ep.index}, expected {missing[k]}")
            files += coll.add(ep)
            successes += bool(ep.success)
            bar.update(1)
            bar.set_postfix(success=f"{successes / (k + 1):.0%}", refresh=False)
            if stop_after and files >= stop_after:
                raise KeyboardInterrupt  # --stop-after-files: behave like Ctrl-C after a complete file
    finally:
        episodes.close()
        bar.close()


def _argv(cfg: CollectConfig) -> list[str]:
    out = []
    for k, v in asdict(cfg).items():
        out += [f"--{k.replace('_', '-')}", str(v)]
    return out
