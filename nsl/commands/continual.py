"""``nsl continual``: fine-tune through a sequence of shifts and measure forgetting and transfer."""

from __future__ import annotations

import argparse

from nsl.commands._options import add_field, add_parser, add_wait
from nsl.services.options import ContinualConfig


def register(sub: argparse._SubParsersAction) -> None:
    from nsl.services import continual

    p = add_parser(
        sub,
        "continual",
        help="fine-tune through a sequence of shifts; performance matrix, forgetting, transfer",
        description=(continual.__doc__ or "").strip(),
    )
    c = ContinualConfig
    add_field(p, c, "sequence", type=str, required=True)
    add_field(p, c, "init")
    add_field(p, c, "base_data")
    p.add_argument("--name", default="continual", help="run name (folder under $NSL_HOME/runs, dataset prefix)")
    for name in ("episodes", "steps", "eval_episodes", "epsilon", "workers", "seed", "single"):
        add_field(p, c, name)
    add_wait(p, "run")
    p.set_defaults(func=run, config=ContinualConfig)


def run(args: argparse.Namespace) -> int:
    from dataclasses import fields

    import nsl

    values = {f.name: getattr(args, f.name) for f in fields(ContinualConfig)}
    values["sequence"] = tuple(s.strip() for s in args.sequence.split(",") if s.strip())
    result = nsl.continual(ContinualConfig(**values), name=args.name, wait=args.wait)
    print(result.metrics.markdown())
    print(f"plots and tables: nsl report {result.run_dir}")
    return 0
