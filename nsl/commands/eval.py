"""``nsl eval``: success rates per shift with 95% Wilson intervals, stored in the catalog."""

from __future__ import annotations

import argparse
import json

from nsl.commands._options import add_field, add_json, add_parser
from nsl.services.options import EvaluateOptions


def register(sub: argparse._SubParsersAction) -> None:
    p = add_parser(
        sub,
        "eval",
        help="success rate of checkpoints or scripted policies per shift, with 95%% intervals",
        description="Evaluate on test objects. Episode i uses scene seed (--seed, i) on every shift and for every "
        "policy, so policies evaluated with the same seed see identical scenes; with two policies a "
        "paired comparison (McNemar's exact test) is printed too. Checkpoint results are stored in the "
        "catalog (they drive ckpt:NAME@best).",
    )
    who = p.add_mutually_exclusive_group()
    who.add_argument(
        "--checkpoint",
        default=None,
        metavar="REF[,REF]",
        help="comma-separated checkpoint refs, e.g. ckpt:base,ckpt:harsh@best",
    )
    who.add_argument(
        "--policy",
        default=None,
        metavar="REF[,REF]",
        help="comma-separated policies: random | oracle[:NOISE] | ckpt:NAME (default: oracle)",
    )
    for name in (
        "shift",
        "severity",
        "episodes",
        "workers",
        "num_envs",
        "split",
        "seed",
        "precision",
        "engine",
        "device",
    ):
        add_field(p, EvaluateOptions, name, **({"type": float} if name == "severity" else {}))
    out = p.add_mutually_exclusive_group()
    add_json(out, 'the results ({"results": {SHIFT: {...}}}, or per policy under "policies")')
    out.add_argument("--markdown", action="store_true", help="print a Markdown table")
    from nsl.cluster import add_option

    add_option(p)  # --cluster local|ray|auto|ray://HOST:PORT
    p.set_defaults(func=run, config=EvaluateOptions)


def run(args: argparse.Namespace) -> int:
    text = args.checkpoint if args.checkpoint else (args.policy or "oracle")
    refs = [r.strip() for r in text.split(",") if r.strip()]
    if args.checkpoint:
        refs = [r if r.startswith("ckpt:") else f"ckpt:{r}" for r in refs]
    from dataclasses import fields

    import nsl

    options = EvaluateOptions(**{f.name: getattr(args, f.name) for f in fields(EvaluateOptions)})
    result = nsl.evaluate(refs, options, progress=not args.json, cluster=args.cluster)
    table, comparisons = result.table, result.paired
    if args.json:
        per = {ref: {"results": {k: v.to_dict() for k, v in res.items()}} for ref, res in table.items()}
        out = {
            "config": result.config.to_dict(),
            "precision": result.precision,
            **(per[refs[0]] if len(refs) == 1 else {"policies": per}),
        }
        if len(refs) == 1:
            out["policy"] = refs[0]
        if comparisons:
            out["paired"] = {s: c.to_dict() for s, c in comparisons.items()}
        print(json.dumps(out, sort_keys=True))
        return 0
    if args.markdown:
        from nsl.eval import markdown_table

        print(markdown_table(table))
    else:
        for ref, results in table.items():
            for name, r in results.items():
                print(f"{ref:<20} {name:<24} {r}")
    for s, c in comparisons.items():
        print(f"paired on {s}: {c}")
    if any(r.startswith("ckpt:") or r == "base" for r in refs):
        print(f"checkpoint policies acted in {result.precision}")
    return 0
