"""``nsl features``: supervised features, the study's ImageNet column (trained on the simulator's objects)."""

from __future__ import annotations

import argparse

from nsl.commands._options import add_field, add_parser, add_wait
from nsl.services.options import FeaturesConfig


def register(sub: argparse._SubParsersAction) -> None:
    from nsl.services import features

    p = add_parser(
        sub,
        "features",
        help="supervised features: a trunk trained on frames of the train objects (or a ResNet from --encoder)",
        description=(features.__doc__ or "").strip(),
    )
    p.add_argument("--name", default="features", help="checkpoint name: the result is ckpt:NAME")
    for name in ("like", "encoder", "label", "classes", "frames", "steps", "batch_size", "lr", "seed"):
        add_field(p, FeaturesConfig, name)
    add_wait(p, "run")
    p.set_defaults(func=run, config=FeaturesConfig)


def run(args: argparse.Namespace) -> int:
    from dataclasses import fields

    import nsl

    result = nsl.features(
        FeaturesConfig(**{f.name: getattr(args, f.name) for f in fields(FeaturesConfig)}),
        name=args.name,
        wait=args.wait,
    )
    print(result.summary())
    return 0
