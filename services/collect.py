"""Collect episodes with a policy in a (shifted) environment into a versioned dataset, and catalogue it.

Episode ``i`` is a pure function of ``(seed, i)``, and episodes are written in
fixed runs of ``episodes_per_file`` through a staging area, so the dataset is
identical for any ``workers`` and whether or not the run was interrupted:
calling it again resumes it.  Asking an existing dataset for more episodes
publishes a new version that appends to the latest one.
"""

from __future__ import annotations

import functools
import shlex
import sys
import time
from dataclasses import asdict

from .options import CollectConfig

__all__ = ["CollectConfig", "collect", "on_version_created"]


def on_version_created(version) -> None:
    """Record a newly published dataset version (a ``DatasetVersion``) in the catalog."""
    from nsl.catalog import Catalog

    from .refs import register_dataset

    with Catalog() as cat:
        register_dataset(cat, version)


def collect(
    cfg: CollectConfig,
    *,
    restart: bool = False,
    stop_after_files: int = 0,
    cluster: str | None = None,
    progress: bool = True,
    register: bool = True,
    wait: bool = False,
):
    """Collect ``cfg.episodes`` episodes into dataset ``cfg.data`` (resuming or appending); returns its DatasetVersion.

    ``restart`` discards an unfinished collection; ``cluster`` runs the episodes on Ray (None: ``$NSL_CLUSTER``
    or local processes).  An interruption raises KeyboardInterrupt with the finished files staged, so the same
    call resumes.  ``register=False`` leaves the catalog alone (:func:`on_version_created` records the version
    later, in the process that writes the catalog).  One process writes a dataset at a time: while another
    holds its writer lock this raises LockedError naming it, or with ``wait`` waits for it (then resumes or
    appends to what it wrote, or finds the dataset up to date).
    """
    from nsl.collectors import EnvConfig
    from nsl.datasets import api

    from .refs import policy_factory

    env_config = EnvConfig(shift=cfg.shift, split=cfg.split, image_size=cfg.image_size, engine=cfg.engine)
    make_policy = policy_factory(
        cfg.policy,
        env_config,
        epsilon=cfg.epsilon,
        action_noise=cfg.action_noise,
        precision=cfg.precision,
        device=cfg.device,
    )
    spec = {"env": env_config.to_dict(), "policy": make_policy().describe(), "policy_ref": cfg.policy, "seed": cfg.seed}
    coll = api.Collection.begin(
        cfg.data, cfg.episodes, spec, cfg.image_size, cfg.episodes_per_file, restart=restart, wait=wait
    )
    with coll:  # holds the dataset's writer lock to the end
        return _run(coll, cfg, env_config, make_policy, stop_after_files, cluster, progress, register)


def _run(coll, cfg: CollectConfig, env_config, make_policy, stop_after_files: int, cluster, progress, register):
    """:func:`collect` once the collection is begun (under the dataset's writer lock)."""
    from nsl.collectors import collect_episodes

    if coll.up_to_date:
        v = coll.parent
        assert v is not None  # only a dataset that already has a version can be up to date
        print(
            f"{v.ref} already holds {v.num_episodes} episodes (asked for {cfg.episodes}); nothing to collect"
            + (f"; use {v.name}:{cfg.episodes} for the first {cfg.episodes}" if cfg.episodes < v.num_episodes else "")
        )
        return v
    missing = coll.missing_indices()
    if len(missing) < coll.stop - coll.start:
        print(
            f"resuming {cfg.data}: {coll.stop - coll.start - len(missing)} of {coll.stop - coll.start} "
            "episodes already staged",
            file=sys.stderr,
        )
    started = time.perf_counter()
    from nsl.cluster import open_executor

    with open_executor(cluster) as ex:  # local processes, or chunks as Ray tasks (same episodes)
        _collect(
            coll,
            cfg,
            env_config,
            make_policy,
            missing,
            stop_after_files,
            progress,
            functools.partial(collect_episodes, runner=ex.runner),
        )
    version = coll.finish(
        created={
            "command": "nsl collect " + shlex.join(_argv(cfg)),
            "workers": cfg.workers,
            "num_envs": cfg.num_envs,
            "cluster": ex.name,
            "collect_seconds": round(time.perf_counter() - started, 2),
            "config": asdict(cfg),
        }
    )
    info = version.describe()
    if register:
        on_version_created(version)
    print(
        f"wrote {version.ref}: {version.num_episodes} episodes ({coll.stop - coll.start} new), "
        f"{version.num_frames} frames, success {info['success_rate']:.1%}, {version.hash[:19]}... "
        f"at {version.root}"
    )
    return version


def _collect(
    coll,
    cfg: CollectConfig,
    env_config,
    make_policy,
    missing: list[int],
    stop_after: int,
    progress: bool,
    collect_episodes,
) -> None:
    from nsl.progress import progress_bar

    if not missing:
        return
    episodes = collect_episodes(
        env_config, make_policy, missing, seed=cfg.seed, workers=cfg.workers, batch=cfg.num_envs
    )
    bar = progress_bar(
        total=len(missing), unit="ep", desc=f"collect {cfg.data}", dynamic_ncols=True, disable=not progress
    )
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
        if (
            (k == "action_noise" and not v)
            or (k == "precision" and v == "fp32")
            or (k == "engine" and v == "mujoco")
            or (k, v) == ("device", "cpu")
        ):
            continue  # options added later: commands without them are recorded as before
        out += [f"--{k.replace('_', '-')}", str(v)]
    return out
