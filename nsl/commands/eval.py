"""``nsl eval``: success rates per shift with 95% Wilson intervals, stored in the catalog."""

from __future__ import annotations

import argparse
import json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "eval", help="success rate of checkpoints or scripted policies per shift, with 95%% intervals",
        description="Evaluate on test objects. Episode i uses scene seed (--seed, i) on every shift and for every "
                    "policy, so policies evaluated with the same seed see identical scenes; with two policies a "
                    "paired comparison (McNemar's exact test) is printed too. Checkpoint results are stored in the "
                    "catalog (they drive ckpt:NAME@best).")
    who = p.add_mutually_exclusive_group()
    who.add_argument("--checkpoint", default=None, metavar="REF[,REF]",
                     help="comma-separated checkpoint refs, e.g. ckpt:base,ckpt:harsh@best")
    who.add_argument("--policy", default=None, metavar="REF[,REF]",
                     help="comma-separated policies: random | oracle[:NOISE] | ckpt:NAME (default oracle)")
    p.add_argument("--shift", default="base", help="comma-separated shift specs, or 'all' (default base)")
    p.add_argument("--severity", type=float, default=None, help="severity for shifts given without @X")
    p.add_argument("--episodes", type=int, default=100, help="episodes per shift (default 100)")
    p.add_argument("--workers", type=int, default=1, help="worker processes (default 1)")
    p.add_argument("--batch", type=int, default=8, help="environments per worker in lock-step (default 8)")
    p.add_argument("--split", default="test", choices=["train", "test"], help="object split (default test)")
    p.add_argument("--seed", type=int, default=1000, help="scene seed (default 1000)")
    p.add_argument("--json", action="store_true", help='print {"results": {SHIFT: {...}}} (one object)')
    p.add_argument("--markdown", action="store_true", help="print a Markdown table")
    from nsl.cluster import add_option

    add_option(p)  # --cluster local|ray|auto|ray://HOST:PORT
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from nsl.collectors import EnvConfig, parse_shift_list
    from nsl.errors import ConfigError
    from nsl.eval import EvalConfig, compare_paired, evaluate_outcomes, markdown_table, success_rate_from_outcomes
    from nsl.resolve import policy_factory

    if args.episodes < 1:
        raise ConfigError(f"--episodes {args.episodes} must be at least 1")
    shifts = parse_shift_list(args.shift, args.severity)
    config = EvalConfig(episodes=args.episodes, split=args.split, seed=args.seed, workers=args.workers,
                        batch=args.batch)
    text = args.checkpoint if args.checkpoint else (args.policy or "oracle")
    refs = [r.strip() for r in text.split(",") if r.strip()]
    if args.checkpoint:
        refs = [r if r.startswith("ckpt:") else f"ckpt:{r}" for r in refs]
    factories = {ref: policy_factory(ref, EnvConfig()) for ref in refs}  # validate all before any work
    from nsl.cluster import open_executor

    with open_executor(args.cluster) as ex:  # local processes, or scene chunks as Ray tasks (same outcomes)
        outcomes = {ref: evaluate_outcomes(make, shifts, config, progress=not args.json, runner=ex.runner)
                    for ref, make in factories.items()}
    table = {ref: {s: success_rate_from_outcomes(s, o) for s, o in res.items()} for ref, res in outcomes.items()}
    _store(table, config)

    comparisons = {}
    if len(refs) == 2:
        a, b = refs
        comparisons = {s: compare_paired(outcomes[a][s], outcomes[b][s], a, b) for s in outcomes[a]}
    if args.json:
        per = {ref: {"results": {k: v.to_dict() for k, v in res.items()}} for ref, res in table.items()}
        out = {"config": config.to_dict(), **(per[refs[0]] if len(refs) == 1 else {"policies": per})}
        if len(refs) == 1:
            out["policy"] = refs[0]
        if comparisons:
            out["paired"] = {s: c.to_dict() for s, c in comparisons.items()}
        print(json.dumps(out, sort_keys=True))
        return 0
    if args.markdown:
        print(markdown_table(table))
    else:
        for ref, results in table.items():
            for name, r in results.items():
                print(f"{ref:<20} {name:<24} {r}")
    for s, c in comparisons.items():
        print(f"paired on {s}: {c}")
    return 0


def _store(table, config) -> None:
    """Record checkpoint evaluations in the catalog."""
    refs = [r for r in table if r.startswith("ckpt:") or r == "base"]
    if not refs:
        return
    from nsl import code_version
    from nsl.catalog import Catalog
    from nsl.resolve import resolve_init

    with Catalog() as cat:
        for ref in refs:
            entry = resolve_init(cat, ref)
            for shift, r in table[ref].items():
                cat.add_evaluation(entry.id, shift, episodes=r.episodes, successes=r.successes, seed=config.seed,
                                   split=config.split, ci=r.ci,
                                   extra={"eval": config.to_dict(), "code_version": code_version()})
            cat.write_model_card(entry.id)
