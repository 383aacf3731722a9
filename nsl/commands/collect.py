"""``nsl collect``: run a policy in a (shifted) environment and record a dataset version.

Episode ``i`` is a pure function of ``(seed, i)``, and episodes are written in
fixed runs of ``--episodes-per-file`` through a staging area, so the dataset is
identical for any ``--workers`` and whether or not the run was interrupted:
running the same command again resumes it.  Asking an existing dataset for more
episodes publishes a new version that appends to the latest one.  The work is
``nsl.collect`` (``nsl.services.collect``).
"""

from __future__ import annotations

import argparse

from nsl.commands._options import add_field, add_parser, add_wait
from nsl.services.options import CollectConfig


def register(sub: argparse._SubParsersAction) -> None:
    p = add_parser(
        sub,
        "collect",
        help="collect grasp episodes into a versioned dataset (resumable, parallel)",
        description="Run a policy for N episodes in a shifted environment and write them as a LeRobot v3.0 "
        "dataset version under $NSL_HOME/datasets/NAME/. Running the same command again resumes an "
        "interrupted collection; asking an existing dataset for more episodes appends a new version.",
        epilog="example: nsl collect --shift harsh_lighting --episodes 800 --policy oracle:0.5 "
        "--data grasp-harsh --workers 2",
    )
    c = CollectConfig
    add_field(p, c, "shift", type=str, required=True)
    add_field(p, c, "episodes", type=int, required=True)
    add_field(p, c, "policy", type=str, required=True)
    add_field(p, c, "data", type=str, required=True, metavar="NAME")
    for name in ("workers", "seed", "epsilon"):
        add_field(p, c, name)
    add_field(p, c, "action_noise", metavar="STD")
    for name in ("num_envs", "split", "image_size", "episodes_per_file", "precision", "engine", "device"):
        add_field(p, c, name)
    p.add_argument("--restart", action="store_true", help="discard an unfinished collection of this dataset")
    add_wait(p, "dataset")
    p.add_argument("--stop-after-files", type=int, default=0, help=argparse.SUPPRESS)  # tests: simulate a kill
    from nsl.cluster import add_option

    add_option(p)  # --cluster local|ray|auto|ray://HOST:PORT
    p.set_defaults(func=run, config=CollectConfig)


def run(args: argparse.Namespace) -> int:
    from dataclasses import fields

    from nsl.services.collect import collect

    config = CollectConfig(**{f.name: getattr(args, f.name) for f in fields(CollectConfig)})
    collect(config, restart=args.restart, stop_after_files=args.stop_after_files, cluster=args.cluster, wait=args.wait)
    return 0
