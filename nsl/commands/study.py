"""``nsl study run|status|report``: the Never Stop Learning study as one resumable command."""

from __future__ import annotations

import argparse

from nsl.commands._options import add_json, add_parser, add_wait, add_workers

CLUSTER_HELP = (
    "where units run: local processes (default, or $NSL_CLUSTER; see --workers), or each unit as a Ray task on "
    "this machine or $RAY_ADDRESS (ray) or an existing cluster (auto, ray://...), as many at once as it has "
    "CPUs; the catalog stays here and NSL_HOME is shared (or see --store); the same numbers (docs/scale.md)"
)


def add_unit_cpus(p) -> None:
    p.add_argument(
        "--unit-cpus",
        type=float,
        default=1.0,
        help="with --cluster: CPUs each unit holds (its torch threads and simulators); default 1",
    )
    p.add_argument(
        "--unit-gpus",
        type=float,
        default=0.0,
        help="with --cluster: GPUs each training unit holds (its plan's device auto then trains there; collections "
        "and evaluations stay on the CPUs); default 0",
    )
    p.add_argument(
        "--store",
        default=None,
        metavar="URL",
        help="with --cluster, when the nodes share no NSL_HOME: an fsspec URL (s3://bucket/prefix, ...; or "
        "$NSL_STORE) through which each unit pulls the folders it reads, checked by sha256 into its node's "
        "cache, and pushes what it makes; credentials as for nsl push (docs/scale.md)",
    )


def run_options(args: argparse.Namespace) -> dict:
    """The options ``nsl study run`` and ``nsl transfer run`` pass on to the scheduler."""
    return {
        "workers": args.workers,
        "progress": not args.quiet,
        "cluster": args.cluster,
        "unit_cpus": args.unit_cpus,
        "unit_gpus": args.unit_gpus,
        "store": args.store,
        "wait": args.wait,
    }


def print_estimate(args: argparse.Namespace, estimate, name) -> int:
    """``--estimate``: the units' cost on this machine, and with --workers W or --cluster their wall time."""
    from nsl.cluster import parse_cluster
    from nsl.study import cluster_slots

    label = name or args.plan
    print(f"{label}: {estimate(args.plan, name)} on a quiet 2-core machine, --workers 1")
    if args.workers > 1 or parse_cluster(args.cluster) != "local":
        slots = cluster_slots(args.cluster, args.workers, args.unit_cpus)
        _, sched = estimate(args.plan, name, slots)
        print(f"{label}: {sched}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = add_parser(
        sub,
        "study",
        help="run the whole study from a plan (resumable), show its progress, write its report",
        description="A study is a TOML plan (shipped: tiny, small, full, paper) run as a graph of collection, "
        "training and evaluation units. Finished units are skipped, so running the same command "
        "again resumes a killed study. Files go to $NSL_HOME/studies/NAME/.",
    )
    ss = p.add_subparsers(dest="study_command", metavar="ACTION")
    r = add_parser(
        ss,
        "run",
        help="run (or resume) a study",
        description="Run every unit of PLAN not done yet, then write the report.",
    )
    r.add_argument("plan", help="a shipped plan (tiny, small, full, paper) or a path to a TOML plan")
    r.add_argument("--name", default=None, help="study name (default: the plan's name)")
    add_workers(
        r,
        help="units run at once, each in its own process (1: one unit at a time, using every core; "
        "results are reproducible for the same --workers)",
    )
    from nsl.cluster import add_option

    add_option(r, help=CLUSTER_HELP)
    add_unit_cpus(r)
    r.add_argument("--quiet", action="store_true", help="no progress bars")
    add_wait(r, "study")
    r.add_argument(
        "--estimate",
        action="store_true",
        help="check the plan and print the estimated time of the units left, then stop (with --workers W or "
        "--cluster: also the wall time with W units, or the cluster's CPUs, at once)",
    )
    r.set_defaults(func=_run)
    s = add_parser(ss, "status", help="units done, running and left, with the time spent")
    s.add_argument("name", help="the study's name (its folder under $NSL_HOME/studies)")
    add_json(s, "the status record")
    s.set_defaults(func=_status)
    w = add_parser(ss, "report", help="write report.md and PNG plots under $NSL_HOME/studies/NAME/")
    w.add_argument("name", help="the study's name (its folder under $NSL_HOME/studies)")
    w.set_defaults(func=_report)
    p.set_defaults(func=lambda args: p.print_help() or 1)


def _run(args: argparse.Namespace) -> int:
    from nsl.study import estimate_study, run_study, status_lines, study_dir

    if args.estimate:
        return print_estimate(args, estimate_study, args.name)
    status = run_study(args.plan, args.name, **run_options(args))
    print("\n".join(status_lines(status)[:1]))
    print(f"report: {study_dir(status['study']) / 'report.md'}")
    return 0


def _status(args: argparse.Namespace) -> int:
    import json

    from nsl.study import status_lines, study_status

    status = study_status(args.name)
    print(json.dumps(status, sort_keys=True) if args.json else "\n".join(status_lines(status)))
    return 0


def _report(args: argparse.Namespace) -> int:
    from nsl.study import write_study_report

    print(f"wrote {write_study_report(args.name)}")
    return 0
