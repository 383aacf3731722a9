"""``nsl transfer run|status|report``: measure the transfer-advantage matrix between tasks (resumable)."""

from __future__ import annotations

import argparse

from nsl.commands._options import add_json, add_parser, add_wait, add_workers


def register(sub: argparse._SubParsersAction) -> None:
    p = add_parser(
        sub,
        "transfer",
        help="measure the transfer-advantage matrix between tasks (resumable); `nsl curriculum` reads it",
        description="A transfer plan (shipped: tiny, small) names tasks: a shift, a checkpoint that has learned it "
        "and its target data. Every ordered pair is fine-tuned (source checkpoint on the target's data) "
        "and every target trained from scratch, recording success curves; A = AUC(fine-tune) / "
        "AUC(scratch). The runs are ordinary catalogued units of the study's scheduler, so running the "
        "same command again resumes. Files go to $NSL_HOME/transfers/NAME/ (docs/transfer.md).",
    )
    ss = p.add_subparsers(dest="transfer_command", metavar="ACTION")
    r = add_parser(
        ss,
        "run",
        help="run (or resume) a transfer plan, then write its matrix",
        description="Run every unit of PLAN not done yet, then write matrix.json and matrix.md.",
    )
    r.add_argument("plan", help="a shipped transfer plan (tiny, small) or a path to a TOML plan")
    r.add_argument("--name", default=None, help="transfer name (default: the plan's name; it prefixes checkpoints)")
    add_workers(r, help="units run at once, each in its own process (1: one unit at a time, using every core)")
    from nsl.cluster import add_option

    from .study import CLUSTER_HELP, add_unit_cpus

    add_option(r, help=CLUSTER_HELP)
    add_unit_cpus(r)
    r.add_argument("--quiet", action="store_true", help="no progress bars")
    add_wait(r, "transfer")
    r.add_argument(
        "--estimate",
        action="store_true",
        help="check the plan and the workspace, print the estimated time of the units left, then stop (with "
        "--workers W or --cluster: also the wall time with W units, or the cluster's CPUs, at once)",
    )
    r.set_defaults(func=_run)
    s = add_parser(ss, "status", help="units done, running and left, with the time spent")
    s.add_argument("name", help="the transfer's name (its folder under $NSL_HOME/transfers)")
    add_json(s, "the status record")
    s.set_defaults(func=_status)
    w = add_parser(ss, "report", help="write matrix.json and matrix.md from the runs finished so far")
    w.add_argument("name", help="the transfer's name (its folder under $NSL_HOME/transfers)")
    add_json(w, "the paths and the proxy's rank correlations")
    w.set_defaults(func=_report)
    c = add_parser(
        ss,
        "curricula",
        help="follow the optimal and pessimal curricula of a finished transfer for real, "
        "and compare their measured cost with the predicted one",
        description="Trains each tree of `nsl curriculum` as a real sequence (each task fine-tuned from "
        "the checkpoint the curriculum made for its parent), with training seeds the matrix "
        "did not use, and measures each edge's advantage, each tree's cost, and whether a "
        "task's transfer depends on how its source was reached. Resumable; writes "
        "$NSL_HOME/transfers/NAME/curricula/curricula.md (docs/transfer.md).",
    )
    c.add_argument("name", help="a transfer whose matrix is complete")
    c.add_argument(
        "--seed",
        type=_seed_list,
        default=None,
        help="training seeds, comma-separated, e.g. 2,3 (default: as many as the matrix's, after its highest)",
    )
    add_workers(c, help="units run at once, each in its own process (1: one unit at a time, using every core)")
    c.add_argument("--quiet", action="store_true", help="no progress bars")
    add_json(c, "the measured and predicted costs")
    c.set_defaults(func=_curricula)
    p.set_defaults(func=lambda args: p.print_help() or 1)


def _seed_list(text: str) -> tuple[int, ...]:
    try:
        seeds = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--seed {text!r} is not a comma-separated list of seeds, e.g. 2,3") from None
    if not seeds or min(seeds) < 0 or len(set(seeds)) != len(seeds):
        raise argparse.ArgumentTypeError(f"--seed {text!r}: give distinct seeds >= 0, e.g. 2,3")
    return seeds


def _summary(out: dict) -> list[str]:
    from nsl.curriculum import Correlation

    lines = [
        f"matrix: {out['matrix']} ({out['measured']} of {out['pairs']} pairs measured)",
        f"report: {out['report']}",
    ]
    lines += [
        f"offline proxy {k} vs measured advantage: {Correlation(**c)}" for k, c in out["rank_correlation"].items()
    ]
    return lines


def _run(args: argparse.Namespace) -> int:
    from nsl.study import estimate_transfer, run_transfer, status_lines

    from .study import print_estimate, run_options

    if args.estimate:
        return print_estimate(args, estimate_transfer, args.name)
    status, report = run_transfer(args.plan, args.name, **run_options(args))
    print("\n".join(status_lines(status, "transfer")[:1]))
    print("\n".join(_summary(report)))
    return 0


def _status(args: argparse.Namespace) -> int:
    import json

    from nsl.study import status_lines, transfer_status

    status = transfer_status(args.name)
    print(json.dumps(status, sort_keys=True) if args.json else "\n".join(status_lines(status, "transfer")))
    return 0


def _report(args: argparse.Namespace) -> int:
    import json

    from nsl.study import write_transfer_report

    out = write_transfer_report(args.name)
    if args.json:
        print(json.dumps({k: str(v) if hasattr(v, "is_file") else v for k, v in out.items()}, sort_keys=True))
        return 0
    print("\n".join(_summary(out)))
    return 0


def _curricula(args: argparse.Namespace) -> int:
    import json

    from nsl.study import run_curricula, status_lines

    status, out = run_curricula(args.name, args.seed, workers=args.workers, progress=not args.quiet)
    if args.json:
        print(json.dumps({k: str(v) if hasattr(v, "is_file") else v for k, v in out.items()}, sort_keys=True))
        return 0
    print("\n".join(status_lines(status, "curricula")[:1]))
    for name, tree in out["trees"].items():
        measured = "n/a" if tree["measured"] is None else f"{tree['measured']:+.2f}"
        print(f"{name} curriculum: predicted cost {tree['predicted']:+.2f}, measured {measured}")
    print(f"report: {out['report']}")
    return 0
