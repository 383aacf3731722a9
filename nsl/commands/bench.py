"""``nsl bench NAME``: speed and memory targets, measured side by side in one run."""

from __future__ import annotations

import argparse
import importlib
import json
import pkgutil

from nsl.commands._options import add_json, add_parser


def register(sub: argparse._SubParsersAction) -> None:
    p = add_parser(
        sub,
        "bench",
        help="run a benchmark (env, data, learner, eval, cluster) and print its figures",
        description="Benchmarks compare nsl against a reference measured in the same invocation.",
    )
    bsub = p.add_subparsers(dest="bench", metavar="NAME", required=True)
    import nsl.bench as benches

    for mod in sorted(pkgutil.iter_modules(benches.__path__), key=lambda m: m.name):
        if mod.name.startswith("_"):
            continue
        module = importlib.import_module(f"nsl.bench.{mod.name}")
        bp = add_parser(bsub, mod.name, help=module.HELP, description=module.HELP)
        add_json(bp, "the figures")
        bp.add_argument("--quick", action="store_true", help="a short run (under a minute)")
        module.add_arguments(bp)
        bp.set_defaults(func=lambda args, m=module: _run(m, args))


def _run(module, args: argparse.Namespace) -> int:
    result = module.run(args)
    if args.json:
        print(json.dumps(result, sort_keys=True))
    else:
        width = max(len(k) for k in result)
        for k, v in result.items():
            print(f"{k:<{width}}  {v:.4g}" if isinstance(v, float) else f"{k:<{width}}  {v}")
    return 0
