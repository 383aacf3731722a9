"""``nsl dataset ls|show|verify|tiers|export``: inspect, check and share dataset versions."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from nsl.commands._options import add_json, add_parser

REF_HELP = "dataset reference NAME[@vN][:K] (latest version by default; :K = first K episodes)"


def register(sub: argparse._SubParsersAction) -> None:
    p = add_parser(
        sub,
        "dataset",
        help="list, show, verify, tier and export datasets",
        description="Datasets live under $NSL_HOME/datasets/NAME/vN/ in LeRobot v3.0 layout.",
    )
    dsub = p.add_subparsers(dest="dataset_command", metavar="ACTION", required=True)

    q = add_parser(dsub, "ls", help="list every dataset version")
    add_json(q, '{"datasets": [...], "unfinished": [...]}')
    q.set_defaults(func=_ls)

    q = add_parser(dsub, "show", help="show a version: size, success rate, hash, provenance")
    q.add_argument("ref", help=REF_HELP)
    add_json(q, "the version's description")
    q.set_defaults(func=_show)

    q = add_parser(dsub, "verify", help="re-hash a version's files against its manifest (all versions if no ref)")
    q.add_argument("ref", nargs="?", help=REF_HELP)
    q.set_defaults(func=_verify)

    q = add_parser(dsub, "tiers", help="the nested first-K tiers of a version with their content hashes")
    q.add_argument("ref", help=REF_HELP)
    q.add_argument("--sizes", default="25,50,100,200,400,800", help="comma-separated tier sizes")
    add_json(q, '{"tiers": [...]}')
    q.set_defaults(func=_tiers)

    q = add_parser(
        dsub,
        "export",
        help="write a version or tier as a plain LeRobot dataset directory",
        description="Write a plain LeRobot v3.0 directory (no nsl-only files, a README.md "
        "dataset card with the provenance), ready for `huggingface-cli upload`.",
    )
    q.add_argument("ref", help=REF_HELP)
    q.add_argument("--out", type=Path, required=True, help="new output directory")
    q.add_argument("--repo-id", default=None, help="hub repo id for the dataset card title (e.g. user/grasp-harsh)")
    q.set_defaults(func=_export)


def _ls(args: argparse.Namespace) -> int:
    from nsl.datasets import api

    rows, pending = api.list_datasets(), api.unfinished()
    if args.json:
        print(json.dumps({"datasets": rows, "unfinished": pending}, sort_keys=True))
        return 0
    if not rows and not pending:
        print("no datasets yet; create one with `nsl collect ... --dataset NAME`")
    if rows:
        _table(rows, ["ref", "episodes", "frames", "success_rate", "shift", "policy", "hash", "created"])
    for r in pending:
        a, b = r["episodes"]
        print(
            f"unfinished: {r['name']} episodes {a}..{b - 1} ({r['settings']}), {r['staged']} of {b - a} staged; "
            "run its `nsl collect` command again to resume"
        )
    return 0


def _show(args: argparse.Namespace) -> int:
    from nsl.datasets import api

    view = api.open_view(args.ref)
    d = {**view.version.describe(), **view.describe()}
    if args.json:
        print(json.dumps(d, sort_keys=True))
        return 0
    prov = d.pop("provenance")
    created = d.pop("created")
    d.pop("version_hash")
    for k, v in d.items():
        print(f"{k:<13} {v:.1%}" if k == "success_rate" else f"{k:<13} {v}")
    for c in prov["collections"]:
        env, spec = c["spec"]["env"], c["spec"]
        print(
            f"collection    episodes {c['episodes'][0]}..{c['episodes'][1] - 1}: shift {env['shift']} "
            f"({env['env_version']}, {env.get('engine', 'mujoco')}, {env['split']} objects), "
            f"policy {spec['policy_ref']}, seed {spec['seed']}"
        )
    print(
        f"created       {created.get('time')} by nsl {created.get('code_version')} "
        f"({created.get('workers', '?')} workers)"
    )
    return 0


def _verify(args: argparse.Namespace) -> int:
    from nsl.datasets import api

    refs = [args.ref] if args.ref else [f"{n}@v{v}" for n in api.dataset_names() for v in api.list_versions(n)]
    for ref in refs:
        r = api.verify(ref)
        print(f"{r['ref']} ok: {r['files']} files, {r['episodes']} episodes, {r['hash']}")
    return 0


def _tiers(args: argparse.Namespace) -> int:
    from nsl.datasets import api
    from nsl.errors import ConfigError

    try:
        sizes = tuple(int(s) for s in args.sizes.split(",") if s.strip())
    except ValueError:
        raise ConfigError(f"--sizes {args.sizes!r} must be comma-separated integers, e.g. 25,50,100") from None
    rows = api.tiers(args.ref, sizes)
    if args.json:
        print(json.dumps({"tiers": rows}, sort_keys=True))
        return 0
    _table(rows, ["ref", "episodes", "frames", "success_rate", "content_hash"])
    print("tiers are nested views: each holds the first K episodes, so every smaller tier lies inside it")
    return 0


def _export(args: argparse.Namespace) -> int:
    from nsl.datasets import api

    out = api.export(args.ref, args.out, args.repo_id)
    print(
        f"exported {args.ref} to {out}; upload with: huggingface-cli upload --repo-type dataset "
        f"{args.repo_id or 'USER/NAME'} {out}"
    )
    return 0


def _table(rows: list[dict[str, Any]], cols: list[str]) -> None:
    def fmt(k: str, v: Any) -> str:
        if k == "success_rate":
            return f"{v:.1%}"
        if k in ("hash", "content_hash"):
            return str(v)[:19]
        return "-" if v is None else str(v)

    cells = [[fmt(k, r.get(k)) for k in cols] for r in rows]
    widths = [max(len(c), *(len(row[i]) for row in cells)) for i, c in enumerate(cols)]
    print("  ".join(c.ljust(w) for c, w in zip(cols, widths)))
    for row in cells:
        print("  ".join(v.ljust(w) for v, w in zip(row, widths)))
