"""``nsl eval``: success rates per shift with 95% Wilson intervals."""

from __future__ import annotations

import argparse
import json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "eval", help="success rate of a policy on one or more shifts, with 95%% intervals",
        description="Evaluate a policy on test objects. Episode i uses scene seed (--seed, i) on every shift and "
                    "for every policy, so two policies evaluated with the same seed see identical scenes.")
    p.add_argument("--policy", default="oracle",
                   help="comma-separated policies: random | oracle[:NOISE] (default oracle)")
    p.add_argument("--shift", default="base", help="comma-separated shift specs, or 'all' (default base)")
    p.add_argument("--severity", type=float, default=None, help="severity for shifts given without @X")
    p.add_argument("--episodes", type=int, default=100, help="episodes per shift (default 100)")
    p.add_argument("--workers", type=int, default=1, help="worker processes (default 1)")
    p.add_argument("--batch", type=int, default=8, help="environments per worker in lock-step (default 8)")
    p.add_argument("--split", default="test", choices=["train", "test"], help="object split (default test)")
    p.add_argument("--seed", type=int, default=1000, help="scene seed (default 1000)")
    p.add_argument("--json", action="store_true", help='print {"results": {SHIFT: {...}}}')
    p.add_argument("--markdown", action="store_true", help="print a Markdown table row")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from nsl.collectors import EnvConfig, parse_shift_list
    from nsl.errors import ConfigError
    from nsl.eval import EvalConfig, evaluate, markdown_table
    from nsl.resolve import policy_factory

    if args.episodes < 1:
        raise ConfigError(f"--episodes {args.episodes} must be at least 1")
    shifts = parse_shift_list(args.shift, args.severity)
    config = EvalConfig(episodes=args.episodes, split=args.split, seed=args.seed, workers=args.workers,
                        batch=args.batch)
    refs = [r.strip() for r in args.policy.split(",") if r.strip()]
    factories = {ref: policy_factory(ref, EnvConfig()) for ref in refs}  # validate all before any work
    table = {ref: evaluate(make, shifts, config, progress=not args.json) for ref, make in factories.items()}
    if args.json:
        out = {"config": config.to_dict(), "policies": {
            ref: {"results": {k: v.to_dict() for k, v in res.items()}} for ref, res in table.items()}}
        if len(refs) == 1:
            out = {"policy": refs[0], "config": config.to_dict(), **out["policies"][refs[0]]}
        print(json.dumps(out, sort_keys=True))
    elif args.markdown:
        print(markdown_table(table))
    else:
        for ref, results in table.items():
            for name, r in results.items():
                print(f"{ref:<14} {name:<24} {r}")
    return 0
