"""``nsl curriculum TASKS...``: the cheapest order to learn tasks, from a measured transfer-advantage matrix."""

from __future__ import annotations

import argparse

from nsl.commands._options import add_json, add_parser


def register(sub: argparse._SubParsersAction) -> None:
    p = add_parser(
        sub,
        "curriculum",
        help="which task to learn from which: optimal and pessimal trees from a transfer matrix",
        description="Reads a transfer-advantage matrix (from `nsl transfer`, or written by hand) as a cost graph "
        "(C = -A, a 'scratch' root whose edges have A = 1) and prints its minimum spanning arborescence "
        "rooted at scratch (the optimal curriculum), the maximum one (pessimal), their predicted costs "
        "and those of learning every task from the base or from scratch; writes a picture of the trees "
        "(docs/transfer.md).",
    )
    p.add_argument("tasks", nargs="*", metavar="TASK", help="tasks to learn (default: every task of the matrix)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--matrix", help="a matrix.json file")
    src.add_argument("--transfer", help="a transfer's name: its $NSL_HOME/transfers/NAME/matrix.json")
    p.add_argument("--out", default=None, help="PNG of the two trees (default: curriculum.png beside the matrix)")
    add_json(p, "the trees and costs")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import json

    import nsl

    result = nsl.build_curriculum(matrix=args.matrix, transfer=args.transfer, tasks=args.tasks or None, out=args.out)
    if args.json:
        print(
            json.dumps(
                {**result.trees.to_dict(), "matrix": str(result.matrix), "picture": str(result.picture)}, sort_keys=True
            )
        )
        return 0
    print("\n".join(result.trees.lines()))
    print(f"picture: {result.picture}")
    return 0
