"""``nsl catalog ls|show|lineage|tag|rm|gc|verify|suggest-base``: browse and maintain the catalog."""

from __future__ import annotations

import argparse
import json
import sys

from nsl.commands._options import add_json, add_parser

EPILOG = """\
references:
  ckpt:NAME              newest checkpoint of NAME      ckpt:NAME@STEP     saved at gradient step STEP
  ckpt:NAME@best         best success on NAME's shift   ckpt:NAME@best:SHIFT  ... on SHIFT
  ckpt:NAME@latest       same as ckpt:NAME              ckpt:NAME@TAG / ckpt:TAG   tagged checkpoint
  data:NAME[@vN][:TIER]  dataset version (default newest), tier for the loader
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = add_parser(
        sub,
        "catalog",
        help="list, inspect and maintain datasets, checkpoints and evaluations",
        description="The catalog ($NSL_HOME/catalog.sqlite) records every dataset version, "
        "checkpoint and evaluation, and where each checkpoint came from.",
        epilog=EPILOG,
    )
    cs = p.add_subparsers(dest="catalog_command", metavar="ACTION", required=True)

    q = add_parser(cs, "ls", help="list entries")
    q.add_argument(
        "kind",
        nargs="?",
        default="all",
        choices=["all", "checkpoints", "datasets", "evals", "tags"],
        help="what to list (default: all)",
    )
    q.add_argument("--name", help="only entries of this checkpoint or dataset name")
    add_json(q, "the entries")
    q.set_defaults(func=run_ls)

    q = add_parser(cs, "show", help="everything about one checkpoint or dataset")
    q.add_argument("ref", help="ckpt:... or data:... (no prefix: a checkpoint)")
    add_json(q, "the entry")
    q.set_defaults(func=run_show)

    q = add_parser(cs, "lineage", help="ancestry tree of a checkpoint, with the data each step used")
    q.add_argument("ref", help="checkpoint reference, e.g. ckpt:harsh@latest")
    q.add_argument("--descendants", action="store_true", help="show what was fine-tuned from it instead")
    q.add_argument("--no-evals", action="store_true", help="leave evaluation results out")
    q.set_defaults(func=run_lineage)

    q = add_parser(
        cs,
        "tag",
        help="point a tag at a checkpoint (ckpt:TAG then resolves to it), or remove one",
        description="nsl catalog tag ckpt:harsh@best harsh-best  |  nsl catalog tag --delete harsh-best",
    )
    q.add_argument("ref", nargs="?", help="checkpoint reference")
    q.add_argument("tag", nargs="?", help="tag name (moves the tag if it exists)")
    q.add_argument("-d", "--delete", metavar="TAG", help="remove this tag")
    q.set_defaults(func=run_tag)

    q = add_parser(cs, "rm", help="remove an entry nothing depends on (and its files in the workspace)")
    q.add_argument("ref", help="ckpt:... or data:NAME@vN")
    q.add_argument("--force", action="store_true", help="remove even if other entries depend on it")
    q.add_argument("--keep-files", action="store_true", help="remove the catalog entry only")
    q.set_defaults(func=run_rm)

    q = add_parser(cs, "gc", help="delete files no catalog entry references (asks first)")
    q.add_argument("--yes", action="store_true", help="do not ask for confirmation")
    q.add_argument("--dry-run", action="store_true", help="only list what would be removed")
    q.add_argument(
        "--min-age", type=float, default=3600.0, help="leave alone anything modified within this many seconds"
    )
    q.set_defaults(func=run_gc)

    q = add_parser(cs, "verify", help="re-hash checkpoint and dataset files; report altered ones")
    q.add_argument("refs", nargs="*", help="entries to check (default: all)")
    q.set_defaults(func=run_verify)

    q = add_parser(
        cs,
        "suggest-base",
        help="rank catalogued checkpoints as the base for a new task",
        description="By the measured transfer advantage where a transfer matrix has it (the checkpoint "
        "of a source task, the new task among its targets), otherwise by an offline proxy "
        "that needs no training: how well the checkpoint's Q-function ranks the target "
        "episodes' successes above their failures (docs/transfer.md).",
    )
    q.add_argument("--shift", required=True, help="the new task: 'base' or a shift spec, e.g. offset_gripper@0.35")
    q.add_argument("--data", required=True, help="its target data, NAME[@vN][:K] (the proxy reads the first episodes)")
    q.add_argument("--episodes", type=int, default=100, help="target episodes the proxy scores each checkpoint on")
    q.add_argument(
        "--proxy",
        choices=["auc", "softopc"],
        default="auc",
        help="auc: Q-ranking AUC of success labels; softopc: SoftOPC",
    )
    src = q.add_mutually_exclusive_group()
    src.add_argument("--matrix", help="a transfer matrix.json with measured advantages")
    src.add_argument("--transfer", help="a transfer's name: its $NSL_HOME/transfers/NAME/matrix.json")
    q.add_argument(
        "--checkpoint",
        action="append",
        default=[],
        help="a candidate (repeat for several; default: the newest checkpoint of every catalogued name)",
    )
    add_json(q, "the ranking")
    q.set_defaults(func=run_suggest_base)


def _open():
    from nsl.catalog import Catalog

    return Catalog()


def _table(headers: list[str], rows: list[list[str]]) -> str:
    if not rows:
        return "  (none)"
    widths = [max(len(str(x)) for x in col) for col in zip(headers, *rows)]
    lines = ["  ".join(str(x).ljust(w) for x, w in zip(r, widths)).rstrip() for r in [headers, *rows]]
    return "\n".join(lines)


def _when(created: str) -> str:
    return created.replace("T", " ").rstrip("Z")


def _pct(x: float) -> str:
    return f"{100 * x:.1f}%"


def _uses(entry) -> str:
    from nsl.catalog import DataUse

    return DataUse.mix(entry.data)


def _ckpt_rows(cat, entries) -> list[list[str]]:
    tags: dict[str, list[str]] = {}
    for t, c in cat.tags().items():
        tags.setdefault(c, []).append(t)
    refs = {c.id: c.ref for c in cat.checkpoints()}
    return [
        [
            c.short_id,
            c.ref,
            c.shift,
            refs.get(c.parent, f"{c.parent[:12]} (removed)") if c.parent else "-",
            _uses(c) or "-",
            ",".join(tags.get(c.id, [])) or "-",
            _when(c.created),
        ]
        for c in entries
    ]


def _eval_rows(cat, evals) -> list[list[str]]:
    refs = {c.id: c.ref for c in cat.checkpoints()}
    return [
        [
            str(e.id),
            refs.get(e.checkpoint, e.checkpoint[:12]),
            e.shift,
            e.split,
            str(e.episodes),
            _pct(e.rate),
            f"{_pct(e.ci_low)}-{_pct(e.ci_high)}",
            str(e.seed),
            _when(e.created),
        ]
        for e in evals
    ]


CKPT_HEAD = ["ID", "CHECKPOINT", "SHIFT", "PARENT", "DATA (x weight)", "TAGS", "CREATED"]
DATA_HEAD = ["DATASET", "SHIFT", "EPISODES", "HASH", "CREATED", "PATH"]
EVAL_HEAD = ["#", "CHECKPOINT", "SHIFT", "OBJECTS", "EPISODES", "SUCCESS", "95% INTERVAL", "SEED", "CREATED"]


def run_ls(args: argparse.Namespace) -> int:
    from nsl.catalog import short_hash

    with _open() as cat:
        ckpts = cat.checkpoints(args.name)
        datas = cat.datasets(args.name)
        ids = {c.id for c in ckpts}
        evals = [e for e in cat.evaluations() if not args.name or e.checkpoint in ids]
        tags = {t: c for t, c in cat.tags().items() if not args.name or c in ids}
        want = {args.kind} if args.kind != "all" else {"checkpoints", "datasets", "evals", "tags"}
        if args.json:
            out = {}
            if "datasets" in want:
                out["datasets"] = [d.to_dict() for d in datas]
            if "checkpoints" in want:
                out["checkpoints"] = [c.to_dict() for c in ckpts]
            if "evals" in want:
                out["evaluations"] = [e.to_dict() for e in evals]
            if "tags" in want:
                out["tags"] = tags
            print(json.dumps(out, indent=2, sort_keys=True))
            return 0
        refs = {c.id: c.ref for c in cat.checkpoints()}
        sections = []
        if "datasets" in want:
            rows = [
                [f"{d.name}@v{d.version}", d.shift_name, str(d.episodes), short_hash(d.hash), _when(d.created), d.path]
                for d in datas
            ]
            sections.append(f"datasets ({len(rows)})\n" + _table(DATA_HEAD, rows))
        if "checkpoints" in want:
            sections.append(f"checkpoints ({len(ckpts)})\n" + _table(CKPT_HEAD, _ckpt_rows(cat, ckpts)))
        if "evals" in want:
            sections.append(f"evaluations ({len(evals)})\n" + _table(EVAL_HEAD, _eval_rows(cat, evals)))
        if "tags" in want:
            rows = [[t, refs.get(c, "?"), c[:12]] for t, c in tags.items()]
            sections.append(f"tags ({len(rows)})\n" + _table(["TAG", "CHECKPOINT", "ID"], rows))
        print("\n\n".join(sections))
    return 0


def run_show(args: argparse.Namespace) -> int:
    from nsl.catalog import CARD_FILE

    with _open() as cat:
        if args.ref.strip().startswith("data:"):
            r = cat.resolve_data(args.ref)
            d = r.dataset
            users = cat.trained_on(d.name, d.version)
            if args.json:
                print(
                    json.dumps(
                        {**d.to_dict(), "tier": r.tier, "trained": [c.id for c in users]}, indent=2, sort_keys=True
                    )
                )
                return 0
            print(f"dataset    {d.name}@v{d.version}" + (f"  (tier {r.tier})" if r.tier else ""))
            print(f"shift      {d.shift_name}\nepisodes   {d.episodes}\nhash       {d.hash}")
            print(f"created    {_when(d.created)}\npath       {d.path}  ({len(d.files)} files)")
            print("provenance " + json.dumps(d.provenance, sort_keys=True))
            print(f"trained    {', '.join(c.ref for c in users) or '-'}")
            return 0
        c = cat.resolve_checkpoint(args.ref)
        evals = cat.evaluations(c.id)
        kids = cat.children(c.id)
        tags = sorted(cat.tags(c.id))
        if args.json:
            print(
                json.dumps(
                    {
                        **c.to_dict(),
                        "evaluations": [e.to_dict() for e in evals],
                        "tags": tags,
                        "children": [k.id for k in kids],
                    },
                    indent=2,
                    sort_keys=True,
                )
            )
            return 0
        parent = cat.lineage(c.id)[1:2]
        print(f"checkpoint {c.ref}\nid         {c.id}\nshift      {c.shift}")
        print(f"parent     {parent[0].ref + ' (' + parent[0].short_id + ')' if parent else (c.parent or '-')}")
        print(f"data       {_uses(c) or '-'}")
        print(f"children   {', '.join(k.ref for k in kids) or '-'}\ntags       {', '.join(tags) or '-'}")
        print(f"code       {c.code_version}\ncreated    {_when(c.created)}\npath       {c.path}")
        print(f"card       {c.path}/{CARD_FILE}")
        print("config     " + json.dumps(c.config, sort_keys=True))
        print(f"evaluations ({len(evals)})\n" + _table(EVAL_HEAD, _eval_rows(cat, evals)))
    return 0


def run_lineage(args: argparse.Namespace) -> int:
    from nsl.catalog import format_descendants, format_lineage

    with _open() as cat:
        if args.descendants:
            print(format_descendants(cat, args.ref))
        else:
            print(format_lineage(cat, args.ref, evaluations=not args.no_evals))
    return 0


def run_tag(args: argparse.Namespace) -> int:
    from nsl.errors import ConfigError

    with _open() as cat:
        if args.delete:
            if args.ref or args.tag:
                raise ConfigError("give either --delete TAG or REF TAG, not both")
            cat.untag(args.delete)
            print(f"removed tag {args.delete}")
            return 0
        if not (args.ref and args.tag):
            raise ConfigError("usage: nsl catalog tag REF TAG (e.g. ckpt:harsh@best harsh-best), or --delete TAG")
        old = cat.tags().get(args.tag)
        entry = cat.tag(args.tag, args.ref)
        moved = f" (moved from {cat.checkpoint(old).ref})" if old and old != entry.id else ""
        print(f"tagged {entry.ref} ({entry.short_id}) as {args.tag}{moved}; use it as ckpt:{args.tag}")
    return 0


def run_rm(args: argparse.Namespace) -> int:
    from nsl.catalog import remove

    with _open() as cat:
        for line in remove(cat, args.ref, force=args.force, delete_files=not args.keep_files):
            print(f"removed {line}")
    return 0


def _size(n: int) -> str:
    for unit in ("B", "KB", "MB", "GB"):
        if n < 1024 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return ""


def run_gc(args: argparse.Namespace) -> int:
    from nsl.catalog import gc_apply, gc_plan

    with _open() as cat:
        items = gc_plan(cat, min_age=args.min_age)
    if not items:
        print("nothing to remove")
        return 0
    for it in items:
        print(f"{_size(it.size):>9}  {it.reason:<32}  {it.path}")
    total = sum(it.size for it in items)
    print(f"{len(items)} item(s), {_size(total)}")
    if args.dry_run:
        return 0
    if not args.yes:
        if not sys.stdin.isatty():
            print("dry run: no terminal to confirm on; run again with --yes to remove these")
            return 0
        if input(f"remove {len(items)} item(s)? [y/N] ").strip().lower() not in ("y", "yes"):
            print("nothing removed")
            return 0
    freed = gc_apply(items)
    print(f"removed {len(items)} item(s), freed {_size(freed)}")
    return 0


def run_verify(args: argparse.Namespace) -> int:
    from nsl.catalog import verify
    from nsl.errors import CorruptDataError

    with _open() as cat:
        report = verify(cat, args.refs, progress=sys.stderr.isatty())
    for p in report.problems:
        print(p)
    if not report.ok:
        raise CorruptDataError(
            f"verify found {len(report.problems)} problem(s) (listed above); restore the files "
            "or remove the entries with `nsl catalog rm --force REF`"
        )
    print(f"ok: {report.checkpoints} checkpoint(s) and {report.datasets} dataset(s) match their registration")
    return 0


def run_suggest_base(args: argparse.Namespace) -> int:
    from nsl.curriculum import Correlation, load_matrix
    from nsl.services.refs import transfer_matrix
    from nsl.study import suggest_base

    matrix = load_matrix(transfer_matrix(args.matrix, args.transfer)) if (args.matrix or args.transfer) else None
    ranked, data = suggest_base(
        args.shift,
        args.data,
        episodes=args.episodes,
        matrix=matrix,
        checkpoints=args.checkpoint,
        proxy=args.proxy,
        progress=sys.stderr.isatty() and not args.json,
    )
    corr = (matrix.meta.get("rank_correlation") or {}).get(args.proxy) if matrix is not None else None
    if args.json:
        print(
            json.dumps(
                {
                    "shift": args.shift,
                    "data": data,
                    "proxy": args.proxy,
                    "rank_correlation": corr,
                    "candidates": [c.to_dict() for c in ranked],
                },
                indent=2,
                sort_keys=True,
            )
        )
        return 0
    rows = [
        [
            str(i),
            c.ref,
            c.shift,
            c.basis,
            "-"
            if c.measured is None
            else f"{c.measured:.2f}" + (f" [{c.interval[0]:.2f}, {c.interval[1]:.2f}]" if c.interval else ""),
            "-" if c.proxy is None else f"{c.proxy:.3f}",
            c.note,
        ]
        for i, c in enumerate(ranked, 1)
    ]
    print(f"bases for {args.shift} (proxy: {args.proxy} on {data})")
    print(_table(["RANK", "CHECKPOINT", "TRAINED FOR", "BY", "ADVANTAGE [95%]", f"PROXY ({args.proxy})", "NOTE"], rows))
    if corr is not None:
        print(f"the proxy against measured advantages in {args.matrix or args.transfer}: {Correlation(**corr)}")
    else:
        print("the proxy's rank correlation with measured transfer is unknown here; `nsl transfer` reports it")
    return 0
