"""``nsl online``: online fine-tuning in rounds; success against the grasps the policy collected."""

from __future__ import annotations

import argparse

from nsl.commands._options import add_field, add_parser, add_wait
from nsl.services.options import OnlineConfig


def register(sub: argparse._SubParsersAction) -> None:
    from nsl.services import online

    p = add_parser(
        sub,
        "online",
        help="online fine-tuning in rounds: collect with the current policy, fine-tune on all of it, repeat",
        description=(online.__doc__ or "").strip(),
    )
    c = OnlineConfig
    add_field(p, c, "shift", required=True)
    add_field(p, c, "init")
    add_field(p, c, "base_data", action="append", default=None)
    p.add_argument("--name", default="online", help="run name (folder under $NSL_HOME/runs, dataset prefix)")
    for name in ("rounds", "episodes", "steps", "ratio", "eval_episodes", "eval_scenes", "epsilon", "workers", "seed"):
        add_field(p, c, name)
    add_field(p, c, "num_envs", type=int)

    add_field(p, c, "method", choices=("ft", "new_head"))
    add_field(p, c, "learner")
    add_field(p, c, "precision")
    add_field(p, c, "device")
    add_field(p, c, "engine")
    add_wait(p, "run")
    p.set_defaults(func=run, config=OnlineConfig)


def run(args: argparse.Namespace) -> int:
    from dataclasses import fields

    import nsl

    values = {f.name: getattr(args, f.name) for f in fields(OnlineConfig)}
    values["base_data"] = tuple(args.base_data) if args.base_data else OnlineConfig.base_data
    result = nsl.online(OnlineConfig(**values), name=args.name, wait=args.wait)
    print(result.markdown())
    return 0
