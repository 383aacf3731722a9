"""The ``nsl`` command line: one subcommand per user action.

Errors from nsl's exception family print as one line (``nsl: error: ...``)
and exit with status 2; ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from nsl import __version__
from nsl.errors import NslError

DESCRIPTION = """\
nsl - never stop learning: offline continual learning for vision-based grasping.

Typical flow:
  nsl render --shift all --out gallery.png        look at the task and its shifts
  nsl collect --shift base --episodes 2000 --policy oracle:0.5 --data grasp-base
  nsl train --data grasp-base --steps 20000 --name base
  nsl eval --checkpoint ckpt:base --shift all --episodes 200

The workspace (datasets, checkpoints, catalog, runs) is $NSL_HOME, default ~/.nsl.
"""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="nsl", description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"nsl {__version__}")
    parser.add_argument("--debug", action="store_true", help="show full tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    import nsl.commands as commands

    for mod in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        if mod.name.startswith("_"):
            continue
        importlib.import_module(f"nsl.commands.{mod.name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    from nsl.commands._options import rename_old_options

    parser = build_parser()
    args = parser.parse_args(rename_old_options(sys.argv[1:] if argv is None else list(argv)))
    if not getattr(args, "func", None):
        parser.print_help()
        return 1
    try:
        result = args.func(args)
    except NslError as e:
        if args.debug:
            raise
        print(f"nsl: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("nsl: interrupted; run the same command again to resume", file=sys.stderr)
        return 130
    return int(result or 0)


if __name__ == "__main__":
    sys.exit(main())
