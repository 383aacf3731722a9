"""``nsl compare``: two methods' catalogued evaluations side by side, with paired hierarchical intervals."""

from __future__ import annotations

import argparse
import json

from nsl.commands._options import add_json, add_parser

DESCRIPTION = """\
Compare method A with method B from their catalogued evaluations (nsl eval stores each scene's outcome);
nothing is evaluated here, and a missing evaluation is an error naming the nsl eval command that makes it.
A side is one checkpoint or several (a method's runs: training seeds on target collections), grouped by
the target dataset and training seed each checkpoint records.

Per shift: each side's success rate (%) and the paired difference A - B in points, with a hierarchical
bootstrap interval (nsl.stats): both sides were scored on the same scenes (--seed, --episodes), so every
replicate draws the scenes once for both; it also redraws each side's training seeds within its target
collections and adds a deviation between collections.  The interval covers the scenes, and the seeds and
collections of a side that has several (a side with one checkpoint is held fixed); the line under each
row says which.

Across the shifts (each run's success rate on each shift is one score; rliable's metrics): the
interquartile mean (IQM, the mean of the middle 50% of run-shift scores), the mean (of each shift's mean
over runs), the optimality gap (how far the scores fall short of 100%, or of --gap-level) and the
probability of improvement P(A > B) (on each shift the chance that a run of A beats a run of B, ties
half, averaged over shifts).
Their intervals are a stratified bootstrap over runs within each shift: they cover run-to-run variation
only, the scenes held fixed.

Writes profile.png (performance profiles: the fraction of run-shift scores above each threshold, both
sides, with bands) and compare.json (every number) to --out.

Example:
  nsl compare ckpt:harsh-s0,ckpt:harsh-s1,ckpt:harsh-s2 ckpt:base --shift harsh_lighting@2,base \\
      --episodes 200 --seed 2000 --labels recipe,base
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = add_parser(
        sub,
        "compare",
        help="compare two methods (sets of checkpoints) per shift and across shifts, with intervals",
        description=DESCRIPTION,
    )
    p.add_argument("a", metavar="A", help="side A: comma-separated checkpoint refs (ckpt:NAME[@STEP], tags, ids)")
    p.add_argument("b", metavar="B", help="side B: comma-separated checkpoint refs, e.g. ckpt:base")
    p.add_argument(
        "--shift",
        required=True,
        help="comma-separated shift specs, or 'all' or 'study' (as in nsl eval); each must be evaluated for every run",
    )
    p.add_argument(
        "--episodes",
        type=int,
        default=None,
        help="the evaluations' episode count (default: the one set of scenes every run was evaluated on)",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=None,
        help="the evaluations' scene seed, as in nsl eval (default: the one set of scenes every run was evaluated on)",
    )
    p.add_argument("--labels", default=None, metavar="A,B", help="names of the two sides (default: their refs)")
    p.add_argument(
        "--out", default=None, help="folder for profile.png and compare.json (default: $NSL_HOME/comparisons/A-vs-B)"
    )
    p.add_argument("--reps", type=int, default=2000, help="bootstrap replicates of every interval")
    p.add_argument("--confidence", type=float, default=0.95, help="level of every interval")
    p.add_argument(
        "--gap-level",
        type=float,
        default=1.0,
        help="the success rate the optimality gap is measured below (default 1.0; e.g. the base policy's "
        "base-task success, to ask how far each method falls short of the level it had before the shift)",
    )
    add_json(p, "every number (what compare.json holds)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import nsl

    labels = [s.strip() for s in args.labels.split(",")] if args.labels else None
    result = nsl.compare(
        args.a,
        args.b,
        shift=args.shift,
        episodes=args.episodes,
        seed=args.seed,
        labels=labels,
        out=args.out,
        reps=args.reps,
        confidence=args.confidence,
        gap_level=args.gap_level,
    )
    if args.json:
        print(json.dumps(result.to_dict(), sort_keys=True))
    else:
        print("\n".join(result.lines()))
    return 0
