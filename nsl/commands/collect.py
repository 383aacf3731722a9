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

from nsl.commands._options import add_env_batch_size, add_parser, add_seed, add_workers
from nsl.errors import ConfigError


@dataclass(frozen=True)
class CollectConfig:
    """What ``nsl collect`` was asked to do (recorded in the dataset's metadata)."""

    shift: str  # shift spec, e.g. "harsh_lighting" or "harsh_lighting+checkerboard_backing@0.5"
    episodes: int  # total episodes the dataset should hold afterwards
    policy: str  # policy reference: random, oracle[:NOISE] or ckpt:NAME[@...] (a checkpoint's CEM policy)
    data: str  # dataset name; an existing name resumes or appends
    workers: int = 1  # simulator processes (does not change the data)
    seed: int = 0  # episode i is a pure function of (seed, i)
    batch_size: int = 1  # environments per worker stepping in lock-step (does not change the data)
    split: str = "train"  # object split: train or test objects
    image_size: int = 64  # camera resolution in pixels
    episodes_per_file: int = 100  # episodes per Parquet file (also the resume granularity)
    epsilon: float = 0.0  # checkpoint policies: probability of a uniformly random action per step (exploration)
    action_noise: float = 0.0  # checkpoint policies: std of Gaussian noise on every action, in action units (exploration)

    def __post_init__(self) -> None:
        if self.episodes < 1:
            raise ConfigError(f"--episodes {self.episodes} must be at least 1")
        if self.workers < 1 or self.batch_size < 1:
            raise ConfigError(f"--workers {self.workers} and --batch-size {self.batch_size} must be at least 1")
        if self.episodes_per_file < 1:
            raise ConfigError(f"--episodes-per-file {self.episodes_per_file} must be at least 1")
        if not 0.0 <= self.epsilon <= 1.0:
            raise ConfigError(f"--epsilon {self.epsilon} must be in [0, 1]")
        if not 0.0 <= self.action_noise <= 2.0:
            raise ConfigError(f"--action-noise {self.action_noise} must be a standard deviation in [0, 2] action units")
        if self.action_noise > 0 and not (self.policy.startswith("ckpt:") or self.policy == "base"):
            raise ConfigError(f"--action-noise applies to checkpoint policies (ckpt:NAME), not {self.policy!r}; "
                              "for the oracle use oracle:NOISE")
        if self.seed < 0:
            raise ConfigError(f"--seed {self.seed} must be non-negative")


def on_version_created(version) -> None:
    """Record a newly published dataset version (a ``DatasetVersion``) in the catalog."""
    from nsl.catalog import Catalog
    from nsl.commands._refs import register_dataset

    with Catalog() as cat:
        register_dataset(cat, version)


def register(sub: argparse._SubParsersAction) -> None:
    p = add_parser(
        sub, "collect", help="collect grasp episodes into a versioned dataset (resumable, parallel)",
        description="Run a policy for N episodes in a shifted environment and write them as a LeRobot v3.0 "
                    "dataset version under $NSL_HOME/datasets/NAME/. Running the same command again resumes an "
                    "interrupted collection; asking an existing dataset for more episodes appends a new version.",
        epilog="example: nsl collect --shift harsh_lighting --episodes 800 --policy oracle:0.5 "
               "--data grasp-harsh --workers 2")
    p.add_argument("--shift", required=True, help="shift spec: base, harsh_lighting, checkerboard_backing@0.5, ...")
    p.add_argument("--episodes", type=int, required=True, help="total episodes the dataset should hold")
    p.add_argument("--policy", required=True, help="policy: random, oracle[:NOISE] (noise std, e.g. oracle:0.5), "
                                                  "or a checkpoint, ckpt:NAME[@STEP] (its CEM policy; see --epsilon)")
    p.add_argument("--data", required=True, metavar="NAME",
                   help="name of the dataset to write (an existing name resumes or appends)")
    add_workers(p, help="simulator processes (the data does not depend on it)")
    add_seed(p, help="collection seed: episode i is a pure function of (seed, i)")
    p.add_argument("--epsilon", type=float, default=0.0,
                   help="with a ckpt: policy, chance of a random action per step (exploration)")
    p.add_argument("--action-noise", type=float, default=0.0, metavar="STD",
                   help="with a ckpt: policy, Gaussian noise of this std (action units; 1 unit moves the wrist 3 cm) "
                        "added to every action: exploration near what the policy would do")
    add_env_batch_size(p, default=1)
    p.add_argument("--split", default="train", choices=["train", "test"], help="object split")
    p.add_argument("--image-size", type=int, default=64, help="camera resolution in pixels")
    p.add_argument("--episodes-per-file", type=int, default=100,
                   help="episodes per Parquet file, also the resume granularity")
    p.add_argument("--restart", action="store_true", help="discard an unfinished collection of this dataset")
    p.add_argument("--stop-after-files", type=int, default=0, help=argparse.SUPPRESS)  # tests: simulate a kill
    from nsl.cluster import add_option

    add_option(p)  # --cluster local|ray|auto|ray://HOST:PORT
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    collect(shift=args.shift, episodes=args.episodes, policy=args.policy, data=args.data, workers=args.workers,
            seed=args.seed, batch_size=args.batch_size, split=args.split, image_size=args.image_size,
            episodes_per_file=args.episodes_per_file, epsilon=args.epsilon, action_noise=args.action_noise,
            restart=args.restart,
            stop_after_files=args.stop_after_files, cluster=args.cluster)
    return 0


def collect(*, shift: str, episodes: int, policy: str, data: str, workers: int = 1, seed: int = 0,
            batch_size: int = 1, split: str = "train", image_size: int = 64, episodes_per_file: int = 100,
            epsilon: float = 0.0, action_noise: float = 0.0, restart: bool = False, stop_after_files: int = 0,
            cluster: str | None = None,
            progress: bool = True):
    """Collect ``episodes`` episodes into dataset ``data`` (resuming or appending); returns its DatasetVersion.

    The keyword arguments are those of ``nsl collect`` (``cluster`` None: ``$NSL_CLUSTER`` or local
    processes).  An interruption raises
    KeyboardInterrupt with the finished files staged, so the same call resumes.
    """
    from nsl.collectors import EnvConfig, collect_episodes
    from nsl.datasets import api
    from nsl.commands._refs import policy_factory

    cfg = CollectConfig(shift=shift, episodes=episodes, policy=policy, data=data, workers=workers, seed=seed,
                        batch_size=batch_size, split=split, image_size=image_size,
                        episodes_per_file=episodes_per_file, epsilon=epsilon, action_noise=action_noise)
    env_config = EnvConfig(shift=cfg.shift, split=cfg.split, image_size=cfg.image_size)
    make_policy = policy_factory(cfg.policy, env_config, epsilon=cfg.epsilon, action_noise=cfg.action_noise)
    spec = {"env": env_config.to_dict(), "policy": make_policy().describe(), "policy_ref": cfg.policy,
            "seed": cfg.seed}
    coll = api.Collection.begin(cfg.data, cfg.episodes, spec, cfg.image_size, cfg.episodes_per_file,
                                restart=restart)
    if coll.up_to_date:
        v = coll.parent
        print(f"{v.ref} already holds {v.num_episodes} episodes (asked for {cfg.episodes}); nothing to collect"
              + (f"; use {v.name}:{cfg.episodes} for the first {cfg.episodes}" if cfg.episodes < v.num_episodes
                 else ""))
        return v
    missing = coll.missing_indices()
    if len(missing) < coll.stop - coll.start:
        print(f"resuming {cfg.data}: {coll.stop - coll.start - len(missing)} of {coll.stop - coll.start} "
              "episodes already staged", file=sys.stderr)
    started = time.perf_counter()
    from nsl.cluster import open_executor

    with open_executor(cluster) as ex:  # local processes, or chunks as Ray tasks (same episodes)
        _collect(coll, cfg, env_config, make_policy, missing, stop_after_files, progress,
                 functools.partial(collect_episodes, runner=ex.runner))
    version = coll.finish(created={
        "command": "nsl collect " + shlex.join(_argv(cfg)), "workers": cfg.workers, "batch_size": cfg.batch_size,
        "cluster": ex.name,
        "collect_seconds": round(time.perf_counter() - started, 2), "config": asdict(cfg)})
    info = version.describe()
    on_version_created(version)
    print(f"wrote {version.ref}: {version.num_episodes} episodes ({coll.stop - coll.start} new), "
          f"{version.num_frames} frames, success {info['success_rate']:.1%}, {version.hash[:19]}... "
          f"at {version.root}")
    return version


def _collect(coll, cfg: CollectConfig, env_config, make_policy, missing: list[int], stop_after: int, progress: bool,
             collect_episodes) -> None:
    from tqdm import tqdm

    if not missing:
        return
    episodes = collect_episodes(env_config, make_policy, missing, seed=cfg.seed, workers=cfg.workers,
                                batch=cfg.batch_size)
    bar = tqdm(total=len(missing), unit="ep", desc=f"collect {cfg.data}", dynamic_ncols=True, disable=not progress)
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
        if k == "action_noise" and not v:
            continue  # an option added later: commands without it are recorded as before
        out += [f"--{k.replace('_', '-')}", str(v)]
    return out
