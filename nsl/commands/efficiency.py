"""``nsl efficiency``: sample efficiency: fine-tune on each dataset tier and evaluate (Table 5.2, Fig. 5.6)."""

from __future__ import annotations

import argparse

from nsl.commands._options import add_field, add_parser, add_wait
from nsl.services.options import EfficiencyConfig


def register(sub: argparse._SubParsersAction) -> None:
    from nsl.services import efficiency

    p = add_parser(
        sub,
        "efficiency",
        help="fine-tune on each dataset tier and evaluate: success vs target attempts",
        description=(efficiency.__doc__ or "").split("\n\n", 1)[1].strip(),
        epilog="example: nsl efficiency --data grasp-harsh --sizes 25,50,100,200,400,800 "
        "--init ckpt:base --base-data grasp-base --name efficiency-harsh",
    )
    c = EfficiencyConfig
    add_field(p, c, "data", action="append", required=True, metavar="REF")
    add_field(p, c, "sizes", type=_sizes)
    add_field(p, c, "init")
    add_field(p, c, "base_data")
    p.add_argument("--name", default="efficiency", help="run name (folder under $NSL_HOME/runs, checkpoint prefix)")
    for name in ("steps", "eval_episodes", "workers", "seed", "scratch"):
        add_field(p, c, name)
    add_wait(p, "run")
    p.set_defaults(func=run, config=EfficiencyConfig)


def _sizes(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(s) for s in text.split(",") if s.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"--sizes {text!r} must be comma-separated integers, e.g. 25,50,100") from None


def run(args: argparse.Namespace) -> int:
    from dataclasses import fields

    import nsl

    values = {f.name: getattr(args, f.name) for f in fields(EfficiencyConfig)}
    nsl.efficiency(EfficiencyConfig(**{**values, "data": tuple(args.data)}), name=args.name, wait=args.wait)
    print(f"plots and tables: nsl report {args.name}")
    return 0
