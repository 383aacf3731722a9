"""``nsl report RUN``: Markdown plus PNG plots from a run folder's records."""

from __future__ import annotations

import argparse
from pathlib import Path

from nsl.commands._options import add_parser


def register(sub: argparse._SubParsersAction) -> None:
    p = add_parser(
        sub,
        "report",
        help="write Markdown and PNG plots (curves, performance matrix, tiers) for a run",
        description="Finds curve.csv (early stopping), matrix.json (continual runs) and tiers.json under RUN and "
        "writes RUN/report/report.md with plots like Fig. 5.6/5.7 and tables like Tables 5.2/5.3. "
        "RUN is a folder or a run name under $NSL_HOME/runs.",
    )
    p.add_argument("run", help="run folder or name")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: RUN/report)")
    p.add_argument("--title", default=None, help="title of the report (default: the run folder's name)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import nsl

    result = nsl.report(args.run, out=args.out, title=args.title)
    print(f"wrote {result.markdown}")
    for fig in result.figures:
        print(f"  {fig}")
    return 0
