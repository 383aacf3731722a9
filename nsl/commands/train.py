"""``nsl train``: pre-train or fine-tune a Q-function offline (QT-Opt, IQL or a plugin learner), and catalogue it."""

from __future__ import annotations

import argparse

from nsl.commands._options import add_field, add_parser, add_wait
from nsl.services.options import TrainOptions

METHODS = (
    "scratch",
    "ft",
    "new_head",
    "new_head_frozen",
    "pnn",
    "ft_pnn",
)  # nsl.learners.METHODS (checked by the test of options)
CRITERIA = ("eval", "softopc", "auc", "td", "qmean", "fqe")  # nsl.eval.CRITERIA


def register(sub: argparse._SubParsersAction) -> None:
    from nsl.learners.config import FINE_TUNE_CONSERVATIVE, FINE_TUNE_LR_FACTOR, FINE_TUNE_STEPS

    p = add_parser(
        sub,
        "train",
        help="pre-train (no --init) or fine-tune (--init CKPT) a Q-function offline",
        description="Offline QT-Opt (or --learner iql, or a plugin's learner) on one or more dataset versions "
        "mixed by weight. Without --init this is "
        "pre-training; with --init it fine-tunes from a catalogued checkpoint with the fine-tuning "
        f"recipe: {FINE_TUNE_STEPS:,} steps at {FINE_TUNE_LR_FACTOR:.0%} of its learning rate, keeping "
        "its n-step returns and crop, with the conservative term at "
        f"{FINE_TUNE_CONSERVATIVE} (mix the target data 50/50 with the base data, as the study did; "
        "docs/learners.md). Running the same command again resumes from the last checkpoint. The final "
        "checkpoint (and, with early stopping, every evaluated one) is registered in the catalog under "
        "--name.",
    )
    c = TrainOptions
    add_field(p, c, "data", action="append", required=True, metavar="REF[=WEIGHT]")
    add_field(p, c, "init", metavar="CKPT")
    add_field(p, c, "method", choices=METHODS)
    add_field(p, c, "learner")
    add_field(p, c, "lr", type=float)
    add_field(p, c, "steps", type=int)
    add_field(p, c, "lr_decay")
    add_field(p, c, "weight_decay")
    add_field(p, c, "name", required=True)
    add_field(p, c, "batch_size")
    add_field(p, c, "seed")
    add_field(p, c, "checkpoint_every")
    add_field(p, c, "no_augment")
    add_field(p, c, "conservative", type=float)
    add_field(p, c, "shrink_perturb", type=str)
    add_field(p, c, "n_step", type=int)
    add_field(p, c, "crop", type=int)
    add_field(p, c, "net", action="append")
    add_field(p, c, "precision")
    add_field(p, c, "device")
    add_wait(p, "run")
    es = p.add_argument_group("early stopping (evaluates every --eval-every steps)")
    for name in ("eval_every", "eval_episodes", "base_episodes", "target_shift", "patience"):
        add_field(es, c, name)
    add_field(es, c, "criterion", choices=CRITERIA)
    add_field(es, c, "holdout")
    add_field(es, c, "eval_scenes")
    add_field(es, c, "workers")
    p.set_defaults(func=run, config=TrainOptions)


def options_from(args: argparse.Namespace) -> TrainOptions:
    """The TrainOptions of parsed ``nsl train`` arguments."""
    from dataclasses import fields

    values = {f.name: getattr(args, f.name) for f in fields(TrainOptions)}
    return TrainOptions(**{**values, "data": tuple(args.data), "net": tuple(args.net or ())})


def run(args: argparse.Namespace) -> int:
    import nsl

    nsl.train(options_from(args), wait=args.wait)
    return 0
